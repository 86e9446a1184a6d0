"""Joint roles: inferred by name for every naming convention, completed by topology, checked by geometry."""

from __future__ import annotations

import dataclasses

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
