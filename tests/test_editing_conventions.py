"""Editing does not depend on how a skeleton is named or laid out (issue 11, "Any skeleton").

A CMU walk is re-expressed in two other conventions, in memory:

* ``renamed``: game-studio ``_L``/``_R`` names (``UpperLeg_L``, ``Foot_L``,
  ``Spine_01`` ...), the same hierarchy and arrays;
* ``static_root``: a static ``joint_Root`` at the origin above the CMU pelvis,
  whose travel is stored in ``Motion.translations`` (6 channels on every
  joint), the layout of many exporters.

Every editing operation (motion path, Laplacian edit, time warp, full-body
refinement, discrete editing) must give the CMU clip's answer, joint for
joint, with no joint name passed anywhere.  ``body(m)`` maps a result back to
the CMU joints (the static root's extra joint 0 dropped).
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest
from conventions import static_root

from mocaplab import quat
from mocaplab.displacement import blend_ramp
from mocaplab.editing import AbsoluteTime, MotionPath, PinPosition, SceneEditor, edit, stationary_segments
from mocaplab.editing import discrete as D
from mocaplab.editing.graph import build_graph, frame_features
from mocaplab.motion import Motion

FPS = 30.0
MM = 1e-3

#: CMU BVH joint name -> game-studio name.
GAME = {"Hips": "Hips", "LowerBack": "Spine_01", "Spine": "Spine_02", "Spine1": "Spine_03"}
GAME.update({"Neck": "Neck_01", "Neck1": "Neck_02", "Head": "Head"})
for _s, _S in (("Left", "L"), ("Right", "R")):
    GAME.update(
        {
            f"{_S}HipJoint": f"HipJoint_{_S}",
            f"{_s}UpLeg": f"UpperLeg_{_S}",
            f"{_s}Leg": f"LowerLeg_{_S}",
            f"{_s}Foot": f"Foot_{_S}",
            f"{_s}ToeBase": f"Toes_{_S}",
            f"{_s}Shoulder": f"Clavicle_{_S}",
            f"{_s}Arm": f"UpperArm_{_S}",
            f"{_s}ForeArm": f"LowerArm_{_S}",
            f"{_s}Hand": f"Hand_{_S}",
            f"{_s}FingerBase": f"Fingers_{_S}",
            f"{_s}HandIndex1": f"Index_{_S}",
            f"{_S}Thumb": f"Thumb_{_S}",
        }
    )


def renamed(m: Motion) -> Motion:
    """``m`` with game-studio ``_L``/``_R`` joint names."""
    return m.replace(skeleton=dataclasses.replace(m.skeleton, names=tuple(GAME[n] for n in m.skeleton.names)))


CONVENTIONS = {"renamed": renamed, "static_root": static_root}


def body(m: Motion) -> np.ndarray:
    """World positions of the CMU joints, (F, 31, 3), whatever the convention."""
    g = m.global_positions()
    return g[:, 1:] if m.skeleton.names[0] == "joint_Root" else g


def name_in(m: Motion, cmu_name: str) -> str:
    """The name of CMU joint ``cmu_name`` in ``m``'s convention."""
    return GAME[cmu_name] if "Foot_L" in m.skeleton.names else cmu_name


@pytest.fixture(autouse=True)
def _quiet_path_joint():
    # Motion.path_joint says once per motion that it follows the pelvis, not joint 0
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="The motion path follows joint")
        yield


@pytest.fixture(scope="module")
def walk(cmu):
    return cmu("16_15")[40:440].resample(FPS)


@pytest.fixture(scope="module", params=sorted(CONVENTIONS))
def other(request, walk):
    return CONVENTIONS[request.param](walk)


def pins(m: Motion) -> list:
    """Hard pins at both ends, a middle pin moved 0.5 m sideways."""
    P = MotionPath.from_motion(m)
    mid = m.n_frames // 2
    side = P.normals[mid] / np.linalg.norm(P.normals[mid])
    return [
        PinPosition(0, 0, P.positions[0], hard=True),
        PinPosition(0, m.n_frames - 1, P.positions[-1], hard=True),
        PinPosition(0, mid, P.positions[mid] + 0.5 * side),
    ]


def test_the_re_expressions_are_the_same_motion(walk, other):
    np.testing.assert_allclose(body(other), body(walk), atol=1e-9)
    feet = tuple(name_in(other, n) for n in walk.skeleton.roles.foot_joints())
    assert other.skeleton.roles.foot_joints() == feet
    assert other.skeleton.names[other.path_joint] == "Hips"
    np.testing.assert_allclose(other.pelvis_positions, walk.root_positions, atol=1e-12)


def test_static_root_really_is_static(walk):
    m = static_root(walk)
    assert m.path_joint == 1
    assert np.ptp(m.root_positions, axis=0).max() == 0.0 and np.ptp(m.global_positions()[:, 0], axis=0).max() == 0.0


# -------------------------------------------------------------- section 3.1
def test_motion_path_follows_the_pelvis(walk, other):
    a, b = MotionPath.from_motion(walk), MotionPath.from_motion(other)
    assert a.length > 2.0
    np.testing.assert_allclose(b.positions, a.positions, atol=1e-12)
    np.testing.assert_allclose(b.tangents, a.tangents, atol=1e-12)
    np.testing.assert_allclose(b.directions, a.directions, atol=1e-12)
    np.testing.assert_allclose(b.headings, a.headings, atol=1e-12)
    assert b.length == pytest.approx(a.length, abs=1e-12)


def test_stationary_segments_use_the_pelvis_and_the_roles_feet(cmu, other):
    stop = cmu("16_34").resample(FPS)  # a walk that stops
    m = (renamed if "Foot_L" in other.skeleton.names else static_root)(stop)
    want = stationary_segments(stop, contacts="auto")
    assert want, "16_34 stops: it has a stationary segment"
    assert stationary_segments(m, contacts="auto") == want
    planted = stationary_segments(stop, contacts="auto", speed=1e-6)  # both feet planted, whatever the speed
    assert planted, "16_34 stands on both feet"
    assert stationary_segments(m, contacts="auto", speed=1e-6) == planted, "both feet planted: the roles' feet"


# -------------------------------------------------------------- section 4
def test_edit_gives_the_same_motion(walk, other):
    ref = edit([walk], pins(walk))
    res = edit([other], pins(other))
    assert res.hard_residual_space < 1e-9
    np.testing.assert_allclose(res.paths[0], ref.paths[0], atol=1e-9)
    moved = np.abs(body(ref.motions[0]) - body(walk)[: ref.motions[0].n_frames]).max()
    assert moved > 0.2, "the middle pin moved the walk"
    assert np.abs(body(res.motions[0]) - body(ref.motions[0])).max() < MM
    assert np.abs(body(res.edited_motions[0]) - body(ref.edited_motions[0])).max() < MM
    # the pelvis is on the edited path
    np.testing.assert_allclose(res.edited_motions[0].pelvis_positions[:, [0, 2]], res.paths[0], atol=1e-9)


def test_a_static_root_stays_static_through_edits(walk):
    """The edit moves the travelling pelvis, not the static reference above it: the same animated channels."""
    other = static_root(walk)
    for res in (edit([other], pins(other)), edit([other], pins(other), refine=True)):
        for out in (res.edited_motions[0], res.motions[0]):
            assert np.ptp(out.root_positions, axis=0).max() < 1e-12
            assert np.ptp(out.rotations[:, 0], axis=0).max() < 1e-12
            np.testing.assert_allclose(out.translations[:, 1], out.pelvis_positions, atol=1e-12)
    ref = edit([walk], pins(walk))
    np.testing.assert_allclose(res.edited_motions[0].rotations[:, 1], ref.edited_motions[0].rotations[:, 0], atol=1e-12)
    # moved far over the ground, still static, still the same body
    far = other.transformed(yaw=np.linspace(0.0, 1.0, other.n_frames), translation=(80.0, 0.0, -30.0))
    assert np.ptp(far.root_positions, axis=0).max() < 1e-12
    here = walk.transformed(yaw=np.linspace(0.0, 1.0, walk.n_frames), translation=(80.0, 0.0, -30.0))
    assert np.abs(body(far) - body(here)).max() < 1e-9


@pytest.mark.parametrize("away", [0.0, 50.0])
def test_time_warp_keeps_the_translations(walk, away):
    """Slowed down and bent, here and 50 m from the origin (where a static joint 0 is a 50 m lever)."""
    conv = {"renamed": renamed, "static_root": static_root}

    def cons(m):
        return pins(m) + [AbsoluteTime(0, 0, 0.0, hard=True), AbsoluteTime(0, m.n_frames - 1, 1.4 * m.duration)]

    here = walk.transformed(translation=(0.8 * away, 0.0, 0.6 * away))
    ref = edit([here], cons(here))
    assert len(ref.clock) > 1.3 * walk.n_frames, "slowed down"
    for name, make in conv.items():
        other = make(here)
        res = edit([other], cons(other))
        np.testing.assert_allclose(res.times[0], ref.times[0], atol=1e-12)
        out = res.motions[0]
        assert (out.translations is None) == (other.translations is None), name
        assert out.n_frames == ref.motions[0].n_frames
        assert np.abs(body(out) - body(ref.motions[0])).max() < 0.2 * MM, name
        np.testing.assert_allclose(out.pelvis_positions, ref.motions[0].root_positions, atol=1e-9)


def test_refinement_plants_the_roles_feet(walk, other):
    ref = edit([walk], pins(walk), refine=True)
    res = edit([other], pins(other), refine=True)
    plain = body(ref.edited_motions[0])
    refined = body(ref.motions[0])
    assert np.abs(refined - body(ref._plain[0])).max() > 1e-3, "refinement changed the edited motion"
    assert plain.shape[1] == refined.shape[1]
    assert np.abs(body(res.motions[0]) - refined).max() < MM


# -------------------------------------------------------------- section 5
def stretched(m: Motion) -> list:
    P = MotionPath.from_motion(m).positions
    return [
        PinPosition(0, 0, P[0], hard=True),
        PinPosition(0, m.n_frames - 1, P[0] + 1.5 * (P[-1] - P[0]), hard=True),
    ]


def test_motion_graph_features_are_the_same(walk, other):
    np.testing.assert_allclose(frame_features(other), frame_features(walk), atol=1e-5)
    a, b = build_graph([walk]), build_graph([other])
    assert len(a.pairs) > 0
    np.testing.assert_array_equal(b.pairs, a.pairs)
    assert b.clip_index(other) == 0 and b.clip_index(other.transformed(yaw=1.0, translation=(2.0, 0.0, 1.0))) == 0


def test_discrete_editing_gives_the_same_motion(walk, other):
    ref = edit([walk], stretched(walk), discrete=True)
    res = edit([other], stretched(other), discrete=True)
    assert ref.transformations, "the stretched walk gains steps"
    assert [str(t) for t in res.transformations] == [str(t) for t in ref.transformations]
    clip = res.characters[0]
    assert (clip.translations is None) == (other.translations is None), "the stitched clip keeps its translations"
    assert np.abs(body(clip) - body(ref.characters[0])).max() < MM
    assert np.abs(body(res.motions[0]) - body(ref.motions[0])).max() < MM


def test_seams_are_blended_in_the_q_exp_d_convention(walk):
    """Around a seam, ``q' = q exp(c d)`` with ``d = log(q_expected^-1 q_actual)`` (mocaplab.displacement).

    On the seam's two frames both conventions give the geodesic midpoint;
    on the others of the blend window they differ (``q`` is not the frame
    ``d`` was measured on), which this test sees.
    """
    track = D.Track.from_motion(walk, build_graph([walk]))
    n = int(round(0.2 * walk.fps))
    # a similar pair whose seam's blend window fits in the clip
    i, j = next((int(a), int(b)) for a, b in track.graph.pairs if a + 1 >= n and b + 1 + n <= walk.n_frames)
    m = D.apply_transformation(
        track, D.Transformation(0, "deletion", (i + 1, j + 1), (0, 0), walk.fps), blend=0.2
    ).motion
    w = blend_ramp((n - np.arange(n)) / n)  # the one blend ramp, 1 at the seam
    q = walk.rotations[:, 1:]  # the body joints (joint 0 carries the placement too)
    d = quat.log(quat.mul(quat.inv(q[i + 1]), q[j + 1]))  # expected i + 1, got j + 1
    d_left = quat.log(quat.mul(q[j + 1], quat.inv(q[i + 1])))  # the same jump, pre-multiplied
    src = np.r_[i - np.arange(n), j + 1 + np.arange(n)]  # graph frames around the seam
    dst = np.r_[i - np.arange(n), i + 1 + np.arange(n)]  # where they play
    c = np.r_[0.5 * w, -0.5 * w][:, None, None]
    right = quat.mul(q[src], quat.exp(c * d))
    left = quat.mul(quat.exp(c * d_left), q[src])
    got = m.rotations[dst, 1:]
    assert quat.angle(quat.mul(quat.inv(got), right)).max() < 1e-9
    assert quat.angle(quat.mul(quat.inv(got), left)).max() > 1e-3, "the other convention would differ"
    # outside the window the body poses are the clip's (joint 0 also carries the placement)
    np.testing.assert_allclose(m.rotations[: i + 1 - n], walk.rotations[: i + 1 - n])
    np.testing.assert_allclose(m.rotations[i + 1 + n :, 1:], walk.rotations[j + 1 + n :, 1:])


def test_seams_have_no_pops_with_a_static_root(walk):
    m0 = static_root(walk)
    track = D.Track.from_motion(m0, build_graph([m0]))
    i, j = (int(v) for v in track.graph.pairs[0])
    m = D.apply_transformation(track, D.Transformation(0, "duplication", (i + 1, i + 1), (i + 1, j + 1), walk.fps))
    m = m.motion
    assert m.translations is not None and m.n_frames == walk.n_frames + (j - i)
    steps = np.linalg.norm(np.diff(m.pelvis_positions[:, [0, 2]], axis=0), axis=1)
    assert steps.max() <= 1.1 * np.linalg.norm(np.diff(walk.root_positions[:, [0, 2]], axis=0), axis=1).max()
    yaw = np.unwrap(quat.yaw(m.pelvis_rotations))
    assert np.abs(np.diff(yaw)).max() <= 1.1 * np.abs(np.diff(np.unwrap(quat.yaw(walk.rotations[:, 0])))).max() + 1e-3


# -------------------------------------------------------------- options
def test_joints_option_chooses_the_contact_joints(walk, other):
    ankles = (name_in(other, "LeftFoot"), name_in(other, "RightFoot"))
    ed = SceneEditor([other], pins(other))
    assert ed.contact_joints(0) == other.skeleton.roles.foot_joints()
    assert SceneEditor([other], pins(other), joints=ed.contact_joints(0)).result.stationary == ed.result.stationary
    only = SceneEditor([other], pins(other), joints=ankles, refine=True)
    assert only.contact_joints(0) == ankles
    full = edit([other], pins(other), refine=True)
    assert np.abs(body(only.result.motions[0]) - body(full.motions[0])).max() > 1e-4, "toes no longer planted"
    with pytest.raises(ValueError, match=r"character 0: Expected `joints` among the skeleton's joints, got \['Nope'\]"):
        edit([other], [], joints=["Nope"])
    with pytest.raises(ValueError, match="one entry per character"):
        edit([other], [], joints=[ankles, ankles])


def test_roles_option_moves_the_path_joint(walk):
    m = renamed(walk)
    spine = m.skeleton.index("Spine_02")
    res = edit([m], [], roles={"pelvis": "Spine_02"})
    assert np.abs(m.global_positions()[:, spine] - m.root_positions).max() > 0.05, "a joint away from the hips"
    np.testing.assert_allclose(res.original_paths[0].positions, m.global_positions()[:, spine][:, [0, 2]], atol=1e-12)
    assert res.characters[0].path_joint == spine and res.motions[0].path_joint == spine
    assert edit([m], []).characters[0].path_joint == 0
    with pytest.raises(ValueError, match="Nope"):
        edit([m], [], roles={"pelvis": "Nope"})
    with pytest.raises(TypeError, match="Expected `roles` to be a mapping"):
        MotionPath.from_motion(m, roles="Spine_02")
