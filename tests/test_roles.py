"""Joint roles: inferred by name for every naming convention, completed by topology, checked by geometry."""

from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest

from mocaplab.io.asfamc import CMU_BVH_NAMES
from mocaplab.motion import Skeleton
from mocaplab.roles import ROLE_NAMES, Roles, RolesError, RolesWarning, infer_roles, mirror_name, parse_name

CMU_ROLES = {
    "pelvis": "Hips",
    "spine": ("LowerBack", "Spine", "Spine1"),
    "neck": "Neck",
    "head": "Head",
    "left_hip": "LeftUpLeg",
    "left_knee": "LeftLeg",
    "left_ankle": "LeftFoot",
    "left_toe": "LeftToeBase",
    "left_clavicle": "LeftShoulder",
    "left_shoulder": "LeftArm",
    "left_elbow": "LeftForeArm",
    "left_wrist": "LeftHand",
}
CMU_ROLES.update({k.replace("left_", "right_"): v.replace("Left", "Right") for k, v in CMU_ROLES.items() if k.startswith("left_")})

# CMU BVH name -> the name another convention gives the same joint
GAME = {
    "Hips": "Hips", "LHipJoint": "HipOffset_L", "LeftUpLeg": "UpperLeg_L", "LeftLeg": "LowerLeg_L",
    "LeftFoot": "Foot_L", "LeftToeBase": "Toes_L", "LowerBack": "Spine_01", "Spine": "Spine_02",
    "Spine1": "Spine_03", "Neck": "Neck_01", "Neck1": "Neck_02", "Head": "Head", "LeftShoulder": "Clavicle_L",
    "LeftArm": "UpperArm_L", "LeftForeArm": "LowerArm_L", "LeftHand": "Hand_L", "LeftFingerBase": "Fingers_L",
    "LeftHandIndex1": "Index_L", "LThumb": "Thumb_L",
}
BIPED = {
    "Hips": "Bip01 Pelvis", "LHipJoint": "Bip01 L HipHelper", "LeftUpLeg": "Bip01 L Thigh", "LeftLeg": "Bip01 L Calf",
    "LeftFoot": "Bip01 L Foot", "LeftToeBase": "Bip01 L Toe0", "LowerBack": "Bip01 Spine", "Spine": "Bip01 Spine1",
    "Spine1": "Bip01 Spine2", "Neck": "Bip01 Neck", "Neck1": "Bip01 Neck1", "Head": "Bip01 Head",
    "LeftShoulder": "Bip01 L Clavicle", "LeftArm": "Bip01 L UpperArm", "LeftForeArm": "Bip01 L Forearm",
    "LeftHand": "Bip01 L Hand", "LeftFingerBase": "Bip01 L Finger0", "LeftHandIndex1": "Bip01 L Finger01",
    "LThumb": "Bip01 L Finger1",
}
LAFAN = {"LeftToeBase": "LeftToe", "LowerBack": "Spine", "Spine": "Spine1", "Spine1": "Spine2"}


def _right(table: dict[str, str]) -> dict[str, str]:
    out = dict(table)
    for k, v in table.items():
        if "Left" in k or k.startswith("L"):
            rk = k.replace("Left", "Right") if "Left" in k else "R" + k[1:]
            out[rk] = mirror_name(v)
    return out


def renamed(sk: Skeleton, table: dict[str, str], prefix: str = "") -> tuple[Skeleton, dict[str, str]]:
    full = _right(table)
    mapping = {n: prefix + full.get(n, n) for n in sk.names}
    return dataclasses.replace(sk, names=tuple(mapping[n] for n in sk.names)), mapping


def expected(mapping: dict[str, str]) -> dict[str, object]:
    return {k: tuple(mapping[x] for x in v) if k == "spine" else mapping[v] for k, v in CMU_ROLES.items()}


@pytest.fixture(scope="module")
def cmu_skeleton(cmu):
    return cmu("16_15").skeleton


def test_cmu_bvh_roles_by_name(cmu_skeleton):
    assert dict(cmu_skeleton.roles) == CMU_ROLES
    assert set(cmu_skeleton.roles) <= set(ROLE_NAMES)


@pytest.mark.parametrize(
    "convention",
    ["asf", "mixamo", "game", "biped", "lafan", "numbers"],
)
def test_roles_of_renamed_cmu_skeletons(cmu_skeleton, convention):
    if convention == "asf":
        inv = {v: k for k, v in CMU_BVH_NAMES.items()}
        sk, mapping = renamed(cmu_skeleton, {}, "")
        mapping = {n: inv[n] for n in cmu_skeleton.names}
        sk = dataclasses.replace(cmu_skeleton, names=tuple(mapping[n] for n in cmu_skeleton.names))
    elif convention == "mixamo":
        sk, mapping = renamed(cmu_skeleton, {"LowerBack": "Spine", "Spine": "Spine1", "Spine1": "Spine2"}, "mixamorig:")
    elif convention == "game":
        sk, mapping = renamed(cmu_skeleton, GAME)
    elif convention == "biped":
        sk, mapping = renamed(cmu_skeleton, BIPED)
    elif convention == "lafan":
        sk, mapping = renamed(cmu_skeleton, LAFAN)
    else:
        # names that say nothing: topology and geometry alone
        mapping = {n: f"joint{i:02d}" for i, n in enumerate(cmu_skeleton.names)}
        sk = dataclasses.replace(cmu_skeleton, names=tuple(mapping[n] for n in cmu_skeleton.names))
        with pytest.warns(RolesWarning, match="geometry"):
            roles = dict(sk.roles)
        assert roles == expected(mapping)
        return
    assert dict(sk.roles) == expected(mapping)
    # mirror pairs are the same joints as on the CMU skeleton
    assert sk.mirror_map().tolist() == cmu_skeleton.mirror_map().tolist()


def test_daz_roles_without_toes(mocap_dir):
    from mocaplab.io import load_bvh

    sk = load_bvh(mocap_dir / "pair_salsa_daz" / "60_10.bvh", scale=0.01).skeleton
    r = sk.roles
    assert (r["pelvis"], r["left_hip"], r["left_knee"], r["left_ankle"]) == ("hip", "lThigh", "lShin", "lFoot")
    assert (r["left_clavicle"], r["left_shoulder"], r["left_elbow"], r["left_wrist"]) == ("lCollar", "lShldr", "lForeArm", "lHand")
    assert r["spine"] == ("abdomen", "chest") and r["neck"] == "neck" and r["head"] == "head"
    assert "left_toe" not in r and "right_toe" not in r
    names = sk.names
    mm = sk.mirror_map()
    assert names[mm[names.index("lButtock")]] == "rButtock"
    assert names[mm[names.index("leftEye")]] == "rightEye"


def smpl_skeleton() -> Skeleton:
    # the 24 SMPL joints with rough adult offsets (metres, Y up, facing +Z)
    names = [
        "pelvis", "left_hip", "right_hip", "spine1", "left_knee", "right_knee", "spine2", "left_ankle",
        "right_ankle", "spine3", "left_foot", "right_foot", "neck", "left_collar", "right_collar", "head",
        "left_shoulder", "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist",
        "left_hand", "right_hand",
    ]
    parents = [-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 20, 21]
    off = {
        "left_hip": (0.09, -0.08, 0), "right_hip": (-0.09, -0.08, 0), "spine1": (0, 0.1, 0),
        "left_knee": (0.02, -0.38, 0), "right_knee": (-0.02, -0.38, 0), "spine2": (0, 0.13, 0),
        "left_ankle": (0, -0.4, -0.02), "right_ankle": (0, -0.4, -0.02), "spine3": (0, 0.05, 0),
        "left_foot": (0, -0.05, 0.12), "right_foot": (0, -0.05, 0.12), "neck": (0, 0.2, 0),
        "left_collar": (0.07, 0.11, 0), "right_collar": (-0.07, 0.11, 0), "head": (0, 0.09, 0.03),
        "left_shoulder": (0.12, 0.04, 0), "right_shoulder": (-0.12, 0.04, 0), "left_elbow": (0.26, 0, 0),
        "right_elbow": (-0.26, 0, 0), "left_wrist": (0.25, 0, 0), "right_wrist": (-0.25, 0, 0),
        "left_hand": (0.08, 0, 0), "right_hand": (-0.08, 0, 0),
    }
    return Skeleton(names, parents, [off.get(n, (0, 0.9, 0)) for n in names])


def test_smpl_roles():
    r = smpl_skeleton().roles
    assert r["pelvis"] == "pelvis" and r["spine"] == ("spine1", "spine2", "spine3")
    assert (r["left_hip"], r["left_knee"], r["left_ankle"], r["left_toe"]) == ("left_hip", "left_knee", "left_ankle", "left_foot")
    assert (r["left_clavicle"], r["left_shoulder"], r["left_elbow"], r["left_wrist"]) == (
        "left_collar", "left_shoulder", "left_elbow", "left_wrist",
    )
    assert r["right_wrist"] == "right_wrist" and r["neck"] == "neck" and r["head"] == "head"


def test_sides_come_from_the_facing_direction(cmu_skeleton):
    # a file whose Left/Right labels are swapped: the left hip is on the body's right
    swapped = {n: mirror_name(n) for n in cmu_skeleton.names}
    sk = dataclasses.replace(cmu_skeleton, names=tuple(swapped[n] for n in cmu_skeleton.names))
    with pytest.warns(RolesWarning, match="swapped"):
        r = sk.roles
    assert r["left_ankle"] == "RightFoot" and r["right_wrist"] == "LeftHand"
    # stating the sides by hand wins
    r2 = sk.with_roles(left_ankle="LeftFoot").roles
    assert r2["left_ankle"] == "LeftFoot"


def test_overrides_complete_the_rest_and_are_kept_by_replace(cmu_skeleton):
    sk = cmu_skeleton.with_roles(left_toe=None, head="Neck1")
    assert sk.roles["head"] == "Neck1" and sk.roles["left_knee"] == "LeftLeg"
    assert cmu_skeleton.roles["head"] == "Head"  # the original is untouched
    assert sk.scaled(2.0).roles["head"] == "Neck1"
    with pytest.raises(RolesError, match="does not have"):
        cmu_skeleton.with_roles(left_ankle="NoSuchJoint")
    with pytest.raises(RolesError, match="Unknown role"):
        cmu_skeleton.with_roles(left_foot="LeftFoot")


def test_missing_roles_error_lists_found_missing_and_the_fix():
    sk = Skeleton(["a", "b", "c"], [-1, 0, 1], [[0, 0, 0], [0, -0.4, 0], [0, -0.4, 0]])
    r = sk.roles
    assert "left_ankle" not in r
    with pytest.raises(RolesError) as err:
        r.require("left_ankle", "right_ankle", purpose="foot contacts")
    msg = str(err.value)
    assert "['left_ankle', 'right_ankle']" in msg and "foot contacts" in msg
    assert 'with_roles(left_ankle="...", right_ankle="...")' in msg and "'a', 'b', 'c'" in msg
    with pytest.raises(RolesError, match="left_knee"):
        r["left_knee"]
    fixed = sk.with_roles(left_ankle="c", right_ankle="c")
    assert fixed.roles["left_knee"] == "b"


def test_degenerate_rest_pose_is_not_used_for_checks(cmu_skeleton):
    # bones laid along +X (rest rotations baked into the motion): names alone decide
    lengths = np.linalg.norm(cmu_skeleton.offsets, axis=-1)
    flat = dataclasses.replace(cmu_skeleton, offsets=np.stack([lengths, 0 * lengths, 0 * lengths], axis=-1))
    assert dict(flat.roles) == CMU_ROLES


def test_parse_and_mirror_names():
    assert parse_name("mixamorig:LeftUpLeg") == ("left", "upleg")
    assert parse_name("Bip01 L Toe0") == ("left", "toe0")
    assert parse_name("lowerback") == (None, "lowerback")
    assert parse_name("rtibia") == ("right", "tibia")
    assert parse_name("Foot.R") == ("right", "foot")
    assert mirror_name("Bip01 L Thigh") == "Bip01 R Thigh"
    assert mirror_name("UpperArm_L") == "UpperArm_R"
    assert mirror_name("mixamorig:RightHand") == "mixamorig:LeftHand"
    assert mirror_name("lowerback") == "lowerback"


def test_roles_mapping_is_immutable(cmu_skeleton):
    r = cmu_skeleton.roles
    assert isinstance(r, Roles)
    with pytest.raises(TypeError):
        r["head"] = "Neck"  # type: ignore[index]
    assert r.index("left_ankle") == cmu_skeleton.index("LeftFoot")
    assert r.foot_joints() == ("LeftFoot", "LeftToeBase", "RightFoot", "RightToeBase")
    assert r.limb("right", "arm") == ("RightArm", "RightForeArm", "RightHand")
    assert infer_roles(cmu_skeleton) == r  # inference is deterministic


# ------------------------------------------- a chain that ends at the neck (issue 22)

# A MotionBuilder HumanIK skeleton without a Head joint, after the shared file
# realworld/motionmachine/animation.bvh (centimetres): the chain ends at Neck
# (with an end site at the top of the head), and the clavicles RightShoulder /
# LeftShoulder start higher than the Neck joint.
HUMANIK = [
    ("Hips", None, [0, 96, 0]),
    ("LeftUpLeg", "Hips", [16.1, 0, 0]), ("LeftLeg", "LeftUpLeg", [2.5, -32.8, 2.1]),
    ("LeftLegRoll", "LeftLeg", [0, 0, 0]), ("LeftFoot", "LeftLegRoll", [2.6, -34.4, -3.3]),
    ("LeftToeBase", "LeftFoot", [5.3, -23.3, 32.4]),
    ("RightUpLeg", "Hips", [-16.1, 0, 0]), ("RightLeg", "RightUpLeg", [-2.5, -32.8, 2.1]),
    ("RightLegRoll", "RightLeg", [0, 0, 0]), ("RightFoot", "RightLegRoll", [-2.6, -34.4, -3.3]),
    ("RightToeBase", "RightFoot", [-5.3, -23.3, 32.4]),
    ("Spine", "Hips", [0, 13.9, 0]), ("Spine1", "Spine", [0, 14.5, 0]), ("Spine2", "Spine1", [0, 23.7, 0]),
    ("Neck", "Spine2", [0, 39.7, 18.0]),
    ("RightShoulder", "Spine2", [-3.4, 45.4, -4.4]), ("RightArm", "RightShoulder", [-47.9, 0.8, 0]),
    ("RightForeArm", "RightArm", [-46.4, -1.3, -0.1]), ("RightHand", "RightForeArm", [-60.8, -1.8, 1.2]),
    ("LeftShoulder", "Spine2", [3.4, 45.4, -4.4]), ("LeftArm", "LeftShoulder", [47.9, 0.8, 0]),
    ("LeftForeArm", "LeftArm", [46.4, -1.3, -0.1]), ("LeftHand", "LeftForeArm", [60.8, -1.8, 1.2]),
]
ARM_ROLES = tuple(f"{s}_{p}" for s in ("left", "right") for p in ("clavicle", "shoulder", "elbow", "wrist"))


def humanik() -> Skeleton:
    names = [n for n, _, _ in HUMANIK]
    ends = {"Neck": [0, 6.6, 13.0], "LeftToeBase": [0, 0, 5], "RightToeBase": [0, 0, 5], "LeftHand": [15, 0, 0],
            "RightHand": [-15, 0, 0]}
    return Skeleton(
        names,
        [-1 if p is None else names.index(p) for _, p, _ in HUMANIK],
        np.array([o for _, _, o in HUMANIK], dtype=float) / 100,
        end_site_parents=[names.index(n) for n in ends],
        end_site_offsets=np.array(list(ends.values()), dtype=float) / 100,
    )


def test_no_head_joint_the_last_neck_joint_is_the_head_never_an_arm():
    sk = humanik()
    assert sk.offsets[sk.index("RightShoulder"), 1] > sk.offsets[sk.index("Neck"), 1]  # the trap: a higher clavicle
    with pytest.warns(RolesWarning, match=r"No head joint: the head is the last neck joint 'Neck'"):
        r = infer_roles(sk)
    assert r["head"] == "Neck" and r["neck"] == "Neck" and r["spine"] == ("Spine", "Spine1", "Spine2")
    assert r["right_clavicle"] == "RightShoulder" and r["right_wrist"] == "RightHand"
    assert r["left_ankle"] == "LeftFoot" and r["left_knee"] == "LeftLeg"  # the roll joint is skipped


def test_no_head_joint_and_no_names_the_head_is_still_no_arm_joint():
    sk = humanik()
    plain = dataclasses.replace(sk, names=tuple(f"j{i:02d}" for i in range(sk.n_joints)))
    with pytest.warns(RolesWarning):
        r = plain.roles
    arms = {sk.names[plain.index(r[k])] for k in ARM_ROLES if k in r}
    assert sk.names[plain.index(r["head"])] == "Neck"
    assert {"RightShoulder", "LeftShoulder", "RightHand", "LeftHand"} <= arms  # both arms found, clavicles included
    assert sk.names[plain.index(r["left_wrist"])] == "LeftHand"  # each arm on the side of its leg


def test_shared_humanik_file_head_and_body(mocap_dir):
    from mocaplab.io import load_bvh
    from mocaplab.physics import Body

    m = load_bvh(mocap_dir / "realworld" / "motionmachine" / "animation.bvh", scale=0.01)
    with pytest.warns(RolesWarning, match="No head joint"):
        r = m.skeleton.roles
    assert r["head"] == "Neck" and r["head"] not in {r[k] for k in ARM_ROLES}
    # what asks the head role keeps working: the body model's head runs from the neck to its end site
    body = Body.from_skeleton(m)
    head = body.link_names.index("head")
    assert body.joint_names[int(body.owners[head])] == "Neck"
    # its centre lies between the neck joint and the end site at the top of the head, in the rest pose
    sk = m.skeleton
    neck = sk.index("Neck")
    top = sk.end_site_offsets[list(sk.end_site_parents).index(neck)]
    assert np.allclose(body.offsets[head], 0.5 * top, atol=1e-9)
    g = m.global_positions()
    assert np.median(g[:, m.skeleton.index("Neck"), 1] - g[:, m.skeleton.index("Hips"), 1]) > 0.4


# ------------------------------------------- not a biped (issue 22)


def quadruped() -> Skeleton:
    """A four-legged figure standing in its rest pose (a dog's proportions, metres), named like a biped."""
    spec: list[tuple[str, str | None, list[float]]] = [("Hips", None, [0.0, 0.6, 0.0])]

    def leg(top: str, side: str, front: bool) -> None:
        x, word = (0.1, "Left") if side == "L" else (-0.1, "Right")
        up, low, foot = ("Arm", "ForeArm", "Hand") if front else ("UpLeg", "Leg", "Foot")
        spec.extend([
            (f"{word}{up}", top, [x, -0.05, 0.0]),
            (f"{word}{low}", f"{word}{up}", [0.0, -0.25, 0.05]),
            (f"{word}{foot}", f"{word}{low}", [0.0, -0.25, -0.05]),
            (f"{word}{foot}End", f"{word}{foot}", [0.0, -0.05, 0.05]),
        ])

    leg("Hips", "L", False)
    leg("Hips", "R", False)
    spec += [("Spine", "Hips", [0.0, 0.02, 0.3]), ("Chest", "Spine", [0.0, 0.0, 0.3])]
    leg("Chest", "L", True)
    leg("Chest", "R", True)
    spec += [("Neck", "Chest", [0.0, 0.15, 0.15]), ("Head", "Neck", [0.0, 0.1, 0.1]), ("Tail", "Hips", [0, 0, -0.3])]
    names = [n for n, _, _ in spec]
    return Skeleton(names, [-1 if p is None else names.index(p) for _, p, _ in spec], [o for _, _, o in spec])


def hand(*, hanging: bool, named: bool) -> Skeleton:
    """A hand: a wrist and five fingers of three bones (fingers along -Y when hanging, else along +Z)."""
    words = ("Thumb", "Index", "Middle", "Ring", "Pinky")
    names, parents, offsets = ["Hand_R" if named else "n00"], [-1], [[0.0, 1.0, 0.0]]
    for f, word in enumerate(words):
        x = 0.02 * (f - 2)
        for k in range(3):
            names.append(f"{word}{k + 1}_R" if named else f"n{len(names):02d}")
            parents.append(0 if k == 0 else len(names) - 2)
            step = [x if k == 0 else 0.0, -0.03, 0.0] if hanging else [x if k == 0 else 0.0, 0.0, 0.03]
            offsets.append(step)
    return Skeleton(names, parents, offsets)


def test_quadruped_is_not_a_biped_and_roles_are_the_way_out():
    sk = quadruped()
    with pytest.raises(RolesError) as info:
        sk.roles  # noqa: B018
    assert str(info.value) == (
        "This skeleton is not a biped human: 4 limbs reach the ground in its pose (['LeftFootEnd', 'RightFootEnd', "
        "'LeftHandEnd', 'RightHandEnd']), a biped stands on two. Joint roles (pelvis, legs, arms, head) are a "
        "human's; to use it anyway, name the joints that play them: skeleton.with_roles(pelvis=..., left_ankle=..., "
        "...) or roles={...} in mocaplab.load and every function that takes roles="
    )
    r = sk.with_roles(left_ankle="LeftFoot", right_ankle="RightFoot").roles  # the hind legs as legs
    assert r["pelvis"] == "Hips" and r["left_knee"] == "LeftLeg" and r["left_wrist"] == "LeftHand"
    # the same figure standing on its hind legs is a biped: the front legs no longer reach the ground
    offsets = np.array(sk.offsets)
    for name in ("Spine", "Chest", "Neck", "Head"):
        offsets[sk.index(name)] = offsets[sk.index(name)][[0, 2, 1]]  # forward becomes up
    for name in ("LeftArm", "RightArm"):
        offsets[sk.index(name)] = [offsets[sk.index(name)][0], 0.0, 0.0]
    for name in ("LeftForeArm", "LeftHand", "LeftHandEnd", "RightForeArm", "RightHand", "RightHandEnd"):
        offsets[sk.index(name)] = [0.0, -0.1, 0.1]
    assert dataclasses.replace(sk, offsets=offsets).roles["left_wrist"] == "LeftHand"


@pytest.mark.parametrize(
    ("hanging", "named", "message"),
    [
        (False, True, "it looks like a hand (5 finger chains: ['Thumb1_R', 'Index1_R', 'Middle1_R', 'Ring1_R', "
         "'Pinky1_R'], no legs)"),
        (True, True, "it looks like a hand"),
        (True, False, "5 limbs reach the ground in its pose"),
    ],
)
def test_hand_is_not_a_biped(hanging, named, message):
    sk = hand(hanging=hanging, named=named)
    with pytest.raises(RolesError, match=re.escape(f"This skeleton is not a biped human: {message}")):
        sk.roles  # noqa: B018
    assert sk.with_roles(pelvis=sk.names[0]).roles["pelvis"] == sk.names[0]  # roles given: no verdict


def test_bipeds_with_many_ground_joints_are_bipeds(cmu_skeleton):
    """Heels, toe ends and foot pinkies are one foot: a biped still stands on two limbs."""
    names = list(cmu_skeleton.names)
    parents = list(cmu_skeleton.parents)
    offsets = list(np.asarray(cmu_skeleton.offsets))
    for foot in ("LeftFoot", "RightFoot"):
        for extra, off in (("Heel", [0.0, -0.02, -0.05]), ("Pinky", [0.03, -0.03, 0.1])):
            names.append(foot + extra)
            parents.append(names.index(foot))
            offsets.append(np.array(off))
    sk = Skeleton(names, parents, np.array(offsets))
    assert sk.roles["left_ankle"] == "LeftFoot" and sk.roles["head"] == "Head"
