"""Body model: link masses, centre of mass, momenta, smoothed derivatives."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from mocaplab import quat
from mocaplab.anatomy import BALL, FOOT_TIP, HAND, HEAD_TOP, TOE_TIP, foot_balls
from mocaplab.motion import Motion, Skeleton
from mocaplab.physics import (
    DE_LEVA_MALE,
    Body,
    LinkSpec,
    angular_momentum,
    balance,
    center_of_mass,
    linear_momentum,
    link_positions,
    smoothed_derivatives,
)
from mocaplab.roles import RolesError


def test_de_leva_table_sums_to_the_whole_body():
    limbs = ("upper_arm", "forearm", "hand", "thigh", "shank", "foot")
    total = sum(v * (2 if k in limbs else 1) for k, v in DE_LEVA_MALE.items())
    assert total == pytest.approx(100.0, abs=0.01)


def test_cmu_body_masses_follow_the_table(cmu):
    walk = cmu("16_15")
    body = Body.from_skeleton(walk, total_mass=80.0)
    assert body.n_links == 17
    assert body.total_mass == pytest.approx(80.0, abs=1e-9)
    m = body.mass_table()
    assert m["left_thigh"] == pytest.approx(0.8 * 14.16)
    assert m["middle_trunk_1"] + m["middle_trunk_2"] == pytest.approx(0.8 * 16.33)
    assert m["upper_trunk"] == pytest.approx(0.8 * 15.96) and m["head"] == pytest.approx(0.8 * 6.94)
    assert m["left_foot"] == m["right_foot"]
    mirror = body.mirror_map()
    assert body.link_names[mirror[body.link_index("left_hand")]] == "right_hand"


def test_daz_skeleton_maps_by_roles(mocap_dir):
    from mocaplab.io import load_bvh

    salsa = load_bvh(mocap_dir / "pair_salsa_daz" / "60_10.bvh", scale=0.01)
    body = Body.from_skeleton(salsa)  # no joint name given anywhere
    assert body.total_mass == pytest.approx(70.0)
    owner = {n: salsa.skeleton.names[j] for n, j in zip(body.link_names, body.owners, strict=True)}
    assert owner["middle_trunk"] == "abdomen" and owner["upper_trunk"] == "chest" and owner["head"] == "head"
    assert owner["left_thigh"] == "lThigh" and owner["right_foot"] == "rFoot" and owner["left_hand"] == "lHand"
    # no toe joint: the support points of a foot belong to the ankle, the tip is its end site
    assert set(body.point_joints) == {"lFoot", "rFoot"} and len(body.point_joints) == 10
    com = center_of_mass(salsa[:20], body)
    hips = salsa.global_positions()[:20, 0]
    # the centre of mass of a standing dancer is near the hips (within 20 cm)
    assert np.all(np.linalg.norm(com - hips, axis=1) < 0.2)


def test_skeleton_without_legs_raises_a_roles_error():
    names = ["Hips", "Spine", "Neck", "Head", "LeftArm", "LeftForeArm", "LeftHand", "RightArm", "RightForeArm", "RightHand"]
    offsets = [[0, 0, 0], [0, 0.3, 0], [0, 0.2, 0], [0, 0.1, 0], [0.2, 0.2, 0], [0.3, 0, 0], [0.25, 0, 0],
               [-0.2, 0.2, 0], [-0.3, 0, 0], [-0.25, 0, 0]]
    sk = Skeleton(names, [-1, 0, 1, 2, 1, 4, 5, 1, 7, 8], offsets)
    with pytest.raises(RolesError, match=r"left_hip.*right_ankle.*body model.*with_roles"):
        Body.from_skeleton(sk)
    with pytest.raises(RolesError, match="left_ankle"):
        Body.from_skeleton(Skeleton(["root", "a"], [-1, 0], [[0, 0, 0], [0, 1, 0]]))


def _stick_figure() -> Skeleton:
    """A T-pose with no toes, fingers, end sites or head top: every estimated point is used."""
    names = ["Hips", "LeftUpLeg", "LeftLeg", "LeftFoot", "RightUpLeg", "RightLeg", "RightFoot",
             "Spine", "Neck", "Head", "LeftArm", "LeftForeArm", "LeftHand", "RightArm", "RightForeArm", "RightHand"]
    parents = [-1, 0, 1, 2, 0, 4, 5, 0, 7, 8, 7, 10, 11, 7, 13, 14]
    offsets = [[0, 1, 0], [0.1, 0, 0], [0, -0.45, 0], [0, -0.45, 0], [-0.1, 0, 0], [0, -0.45, 0], [0, -0.45, 0],
               [0, 0.5, 0], [0, 0.1, 0], [0, 0.1, 0], [0.2, 0.0, 0], [0.3, 0, 0], [0.25, 0, 0],
               [-0.2, 0.0, 0], [-0.3, 0, 0], [-0.25, 0, 0]]
    return Skeleton(names, parents, offsets)


def test_points_a_skeleton_lacks_are_estimated_as_documented():
    sk = _stick_figure()
    body = Body.from_skeleton(sk, foot_width=0.0, heel=0.05)
    leg = 0.9
    link = {n: (sk.names[j], off) for n, j, off in zip(body.link_names, body.owners, body.offsets, strict=True)}
    # one trunk bone (Spine to Neck): middle trunk at a quarter, upper trunk at three quarters
    assert link["middle_trunk"][0] == "Spine" and np.allclose(link["middle_trunk"][1], [0, 0.025, 0])
    assert link["upper_trunk"][0] == "Spine" and np.allclose(link["upper_trunk"][1], [0, 0.075, 0])
    # head: neck to HEAD_TOP leg lengths above the head joint, owned by the joint below its centre
    top = 0.1 + HEAD_TOP * leg  # above the neck: the centre (0.102) is just above the head joint (0.1)
    assert link["head"][0] == "Head" and np.allclose(link["head"][1], [0, top / 2 - 0.1, 0])
    # hand: HAND forearm lengths beyond the wrist
    assert np.allclose(link["left_hand"][1], [HAND * 0.25 / 2, 0, 0])
    # feet face +z (left is +x, up is +y); tip FOOT_TIP ahead of and below the ankle, ball BALL of the way
    tip = np.array([0.0, -FOOT_TIP[1] * leg, FOOT_TIP[0] * leg])
    assert np.allclose(link["left_foot"][1], tip / 2)
    left = [k for k, n in enumerate(body.point_joints) if n == "LeftFoot"]
    assert np.allclose(body.point_offsets[left], [[0, 0, -0.05], BALL * tip, tip])


def test_foot_balls_are_the_body_models_balls_carried_by_the_ankles(cmu):
    """The ball contacts label toe-off by (mocaplab.anatomy.foot_balls) is the body's ball support point."""
    sk = _stick_figure()
    turns = quat.from_axis_angle([0.0, 1.0, 0.0], np.linspace(0.0, 1.5, 4))  # the figure turns about y, knees bent
    rot = np.tile(quat.identity((1, sk.n_joints)), (4, 1, 1))
    rot[:, 0] = turns
    rot[:, sk.index("LeftLeg")] = quat.from_axis_angle([1.0, 0.0, 0.0], np.linspace(0.0, 0.6, 4))
    walk = Motion(sk, rot, np.array([[0.0, 1.0, 0.1 * f] for f in range(4)]), fps=30.0)
    balls = foot_balls(walk)
    assert sorted(balls) == ["LeftFoot", "RightFoot"]
    leg = 0.9
    g, gr = walk.global_positions(), walk.global_rotations()
    ankle = sk.index("LeftFoot")
    ball = BALL * np.array([0.0, -FOOT_TIP[1] * leg, FOOT_TIP[0] * leg])  # ahead (+z) of and below the ankle
    assert np.allclose(balls["LeftFoot"], g[:, ankle] + quat.rotate(gr[:, ankle], ball))
    body = Body.from_skeleton(walk, foot_width=0.0)
    pts, _ = body.support_points(walk, ("LeftFoot", "RightFoot"))  # heel, ball, tip per foot
    assert np.allclose(pts[:, 1], balls["LeftFoot"]) and np.allclose(pts[:, 4], balls["RightFoot"])
    assert foot_balls(cmu("16_15")[:3]) == {}  # every CMU foot has a toe joint


def test_zeroed_end_sites_give_nearly_the_same_support_polygon(cmu):
    """Toe tips without end sites are estimated from the foot (TOE_TIP of the ankle-to-ball distance ahead)."""
    walk = cmu("16_15")[:240]
    sk = walk.skeleton
    bare = walk.replace(skeleton=dataclasses.replace(sk, end_site_offsets=np.zeros_like(sk.end_site_offsets)))
    b0, b1 = Body.from_skeleton(walk), Body.from_skeleton(bare)
    assert np.array_equal(b0.masses, b1.masses) and b0.point_joints == b1.point_joints
    changed = np.linalg.norm(b0.point_offsets - b1.point_offsets, axis=1)
    assert np.count_nonzero(changed) == 2 and changed.max() < 0.008  # the two toe tips, within 8 mm
    s0, s1 = balance(walk, b0), balance(bare, b1)
    assert np.abs(s0.support - s1.support).max() < 0.008
    assert np.nanmax(np.abs(s0.distance - s1.distance)) < 0.008
    # and the estimate follows the documented rule
    toe = sk.index("LeftToeBase")
    ahead = sk.offsets[toe] * [1.0, 0.0, 1.0]
    assert np.allclose(b1.point_offsets[b1.point_joints.index("LeftToeBase") + 2], TOE_TIP * ahead)


# ------------------------------------------------------------ other layouts
#: CMU BVH names in a game-studio convention (``_L``/``_R`` suffixes, numbered spine).
GAME_STUDIO = {
    "Hips": "Hips", "LowerBack": "Spine_01", "Spine": "Spine_02", "Spine1": "Spine_03", "Neck": "Neck_01",
    "Neck1": "Neck_02", "Head": "Head",
} | {
    cmu_name: ours
    for side, s in (("Left", "L"), ("Right", "R"))
    for cmu_name, ours in (
        (f"{side[0]}HipJoint", f"HipRoot_{s}"), (f"{side}UpLeg", f"UpperLeg_{s}"), (f"{side}Leg", f"LowerLeg_{s}"),
        (f"{side}Foot", f"Foot_{s}"), (f"{side}ToeBase", f"Toes_{s}"), (f"{side}Shoulder", f"Clavicle_{s}"),
        (f"{side}Arm", f"UpperArm_{s}"), (f"{side}ForeArm", f"LowerArm_{s}"), (f"{side}Hand", f"Hand_{s}"),
        (f"{side}FingerBase", f"Palm_{s}"), (f"{side}HandIndex1", f"Index_01_{s}"), (f"{side[0]}Thumb", f"Thumb_01_{s}"),
    )
}


def game_studio(motion: Motion) -> Motion:
    """The CMU clip with its joints renamed (:data:`GAME_STUDIO`), same hierarchy."""
    sk = motion.skeleton
    return motion.replace(skeleton=dataclasses.replace(sk, names=tuple(GAME_STUDIO[n] for n in sk.names)))


def unnamed(motion: Motion) -> Motion:
    """The CMU clip with joints called ``j00`` ... (roles from the hierarchy and the geometry alone)."""
    sk = motion.skeleton
    return motion.replace(skeleton=dataclasses.replace(sk, names=tuple(f"j{k:02d}" for k in range(sk.n_joints))))


def static_root(motion: Motion) -> Motion:
    """The CMU clip below a new joint 0 that never moves; the pelvis carries the root translation.

    Joint ``k`` of the CMU clip is joint ``k + 1`` here.
    """
    sk = motion.skeleton
    n, f = sk.n_joints, motion.n_frames
    parents = np.concatenate([[-1], np.where(sk.parents < 0, 0, sk.parents + 1)])
    offsets = np.vstack([np.zeros(3), sk.offsets])
    new = Skeleton(("joint_Root",) + sk.names, parents, offsets,
                   end_site_parents=sk.end_site_parents + 1, end_site_offsets=sk.end_site_offsets)
    rot = np.concatenate([np.tile([0.0, 0.0, 0.0, 1.0], (f, 1, 1)), motion.rotations], axis=1)
    tr = np.array(np.broadcast_to(offsets, (f, n + 1, 3)))
    tr[:, 1] = motion.root_positions
    return Motion(new, rot, np.zeros((f, 3)), motion.fps, translations=tr, name=motion.name)


LAYOUTS = {"game_studio": (game_studio, 0), "unnamed": (unnamed, 0), "static_root": (static_root, 1)}


@pytest.mark.filterwarnings("ignore::UserWarning")
@pytest.mark.parametrize("layout", sorted(LAYOUTS))
def test_body_and_zmp_do_not_depend_on_names_or_a_static_root(cmu, layout):
    convert, shift = LAYOUTS[layout]
    walk = cmu("16_15")[:240]
    other = convert(walk)
    b0, b1 = Body.from_skeleton(walk), Body.from_skeleton(other)  # no name given
    assert b1.link_names == b0.link_names and np.array_equal(b1.masses, b0.masses)
    assert np.array_equal(b1.owners, b0.owners + shift) and np.array_equal(b1.point_owners, b0.point_owners + shift)
    assert np.allclose(b1.offsets, b0.offsets, atol=1e-12) and np.allclose(b1.point_offsets, b0.point_offsets, atol=1e-12)
    assert np.abs(center_of_mass(other, b1) - center_of_mass(walk, b0)).max() < 1e-3
    s0, s1 = balance(walk, b0), balance(other, b1)  # default contacts from the roles
    assert np.array_equal(s1.ground, s0.ground) and np.array_equal(s1.active, s0.active)
    assert np.nanmax(np.abs(s1.zmp - s0.zmp)) < 1e-3 and np.nanmax(np.abs(s1.distance - s0.distance)) < 1e-3


def test_roles_overrides_reach_the_body_and_the_balance(cmu):
    walk = cmu("16_15")[:120]
    # the neck taken one joint higher: three middle-trunk bones, the upper trunk on Neck-Neck1
    body = Body.from_skeleton(walk, roles={"neck": "Neck1"})
    names = walk.skeleton.names
    owner = {n: names[j] for n, j in zip(body.link_names, body.owners, strict=True)}
    assert [owner[f"middle_trunk_{k}"] for k in (1, 2, 3)] == ["LowerBack", "Spine", "Spine1"]
    assert owner["upper_trunk"] == "Neck" and body.total_mass == pytest.approx(70.0)
    moved = balance(walk, roles={"neck": "Neck1"})
    assert np.allclose(moved.com, center_of_mass(walk, body))
    assert np.nanmax(np.abs(moved.com - balance(walk).com)) > 1e-3


def test_from_links_and_validation():
    sk = Skeleton(["root", "a"], [-1, 0], [[0, 0, 0], [0, 1.0, 0]])
    body = Body.from_links(sk, [LinkSpec("rod", "thigh", 1.0, "root", ("root",), ("a",))], total_mass=100.0)
    assert body.offsets[0].tolist() == [0.0, 0.5, 0.0]
    assert body.masses[0] == pytest.approx(14.16)
    with pytest.raises(ValueError, match="masses"):
        body.with_masses([-1.0])
    with pytest.raises(KeyError, match="mass table"):
        Body.from_links(sk, [LinkSpec("rod", "tail", 1.0, "root", ("root",), ("a",))])


def _rod_motion(n: int = 60, fps: float = 30.0, spin: float = 0.0, velocity=(0.0, 0.0, 0.0)) -> tuple[Motion, Body]:
    """Two masses on a horizontal rod, spinning about +Y and translating."""
    sk = Skeleton(["root", "tip"], [-1, 0], [[0, 0, 0], [1.0, 0, 0]])
    t = np.arange(n) / fps
    rot = np.zeros((n, 2, 4))
    rot[:, 0] = quat.from_yaw(spin * t)
    rot[:, 1, 3] = 1.0
    root = np.outer(t, velocity) + [0.0, 1.0, 0.0]
    m = Motion(sk, rot, root, fps)
    body = Body.from_links(
        sk,
        [
            LinkSpec("near", "thigh", 1.0, "root", ("root",), ("root",)),
            LinkSpec("far", "thigh", 1.0, "tip", ("tip",), ("tip",)),
        ],
        total_mass=100.0 / 14.16,
    )
    return m, body


def test_com_and_linear_momentum_of_a_translating_body():
    m, body = _rod_motion(velocity=(0.5, 0.0, -1.0))
    com = center_of_mass(m, body)
    assert np.allclose(com[0], [0.5, 1.0, 0.0])
    p = linear_momentum(m, body)
    assert np.allclose(p, body.total_mass * np.array([0.5, 0.0, -1.0]), atol=1e-9)
    # a pure translation has no angular momentum about the centre of mass
    assert np.allclose(angular_momentum(m, body), 0.0, atol=1e-9)


def test_angular_momentum_of_a_spinning_rod_is_i_omega():
    m, body = _rod_motion(n=240, fps=120.0, spin=2.0)
    h = angular_momentum(m, body, width=0.0)
    # two unit masses 1 m apart spin about the first: about the COM, I = 2 * 0.5^2
    assert np.allclose(h[:, 1], 0.5 * 2.0, rtol=1e-3)
    assert np.allclose(h[:, [0, 2]], 0.0, atol=1e-9)
    # about the rod's first mass: I = 1
    h0 = angular_momentum(m, body, about=m.root_positions, width=0.0)
    assert np.allclose(h0[:, 1], 2.0, rtol=1e-3)
    # the default smoothing (5 frames at 30 fps) shrinks a 2 rad/s spin by < 1 %
    assert np.allclose(angular_momentum(m, body)[:, 1], 1.0, rtol=1e-2)


def test_smoothed_derivatives_are_exact_for_parabolas():
    t = np.arange(50) / 30.0
    x = np.stack([3 * t**2 - t + 1, -4.905 * t**2 + 2 * t], axis=1)
    for width in (0.0, 5.0, 40.0):
        _, v, a = smoothed_derivatives(x, 30.0, width=width)
        assert np.allclose(a, [6.0, -9.81], atol=1e-8)
        assert np.allclose(v, np.stack([6 * t - 1, -9.81 * t + 2], axis=1), atol=1e-8)


def test_smoothed_derivatives_short_clips_do_not_fail():
    for n in (1, 2, 3):
        s, v, a = smoothed_derivatives(np.arange(n, dtype=float)[:, None], 30.0, width=5.0)
        assert s.shape == v.shape == a.shape == (n, 1)
        assert np.all(np.isfinite(a))


def test_link_positions_checks_the_skeleton(cmu):
    walk, salsa = cmu("16_15"), cmu("60_10")
    body = Body.from_skeleton(walk)
    assert link_positions(walk[:3], body).shape == (3, 17, 3)
    with pytest.raises(ValueError, match="skeleton"):
        link_positions(salsa[:3], body)


def test_support_points_give_heel_and_toe_points(cmu):
    walk = cmu("16_15")[:5]
    body = Body.from_skeleton(walk, foot_width=0.0)
    pts, col = body.support_points(walk, ("LeftFoot", "LeftToeBase", "Head"))
    assert col.tolist() == [0, 1, 1, 2]
    g = walk.global_positions()
    ankle, ball = g[:, walk.skeleton.index("LeftFoot")], g[:, walk.skeleton.index("LeftToeBase")]
    heel = pts[:, 0]
    # the heel lies behind the ankle, the toe points ahead of the ball, along the foot
    fwd = (ball - ankle)[:, [0, 2]]
    assert np.all(np.einsum("fc,fc->f", (heel - ankle)[:, [0, 2]], fwd) < 0)
    assert np.allclose(pts[:, 1], ball)
    assert np.all(np.einsum("fc,fc->f", (pts[:, 2] - ball)[:, [0, 2]], fwd) > 0)
    assert np.allclose(pts[:, 3], g[:, walk.skeleton.index("Head")])
