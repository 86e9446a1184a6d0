"""Staggered poses on any skeleton: joint names and layouts do not change the results.

A CMU clip is re-expressed (a) with game-studio joint names (``UpperLeg_L``,
``Foot_L``, ``Spine_01`` ...) and (b) below a static joint 0 at the origin,
with the travel of the pelvis in ``Motion.translations`` and translation
channels on every joint (a common export layout).  Extraction, evaluation,
edits and the contact constraint layer must give the same poses, times and
joint positions, with no joint name passed anywhere.
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest

from mocaplab import quat
from mocaplab.motion import Motion, Skeleton
from mocaplab.staggered import (
    StaggeredEditor,
    StaggeredTimingWarning,
    default_joint,
    delete_pose,
    edit_pose,
    exaggerate,
    extract,
    insert_pose,
    retime,
    succession,
    succession_depths,
)

# CMU name -> game-studio name (no CMU word left but Hips, Neck, Head)
STUDIO = {
    "Hips": "Hips", "LHipJoint": "HipJoint_L", "LeftUpLeg": "UpperLeg_L", "LeftLeg": "LowerLeg_L",
    "LeftFoot": "Foot_L", "LeftToeBase": "Toes_L", "RHipJoint": "HipJoint_R", "RightUpLeg": "UpperLeg_R",
    "RightLeg": "LowerLeg_R", "RightFoot": "Foot_R", "RightToeBase": "Toes_R", "LowerBack": "Spine_01",
    "Spine": "Spine_02", "Spine1": "Spine_03", "Neck": "Neck", "Neck1": "Neck_01", "Head": "Head",
    "LeftShoulder": "Clavicle_L", "LeftArm": "UpperArm_L", "LeftForeArm": "LowerArm_L", "LeftHand": "Hand_L",
    "LeftFingerBase": "Fingers_L", "LeftHandIndex1": "Index_L", "LThumb": "Thumb_L",
    "RightShoulder": "Clavicle_R", "RightArm": "UpperArm_R", "RightForeArm": "LowerArm_R", "RightHand": "Hand_R",
    "RightFingerBase": "Fingers_R", "RightHandIndex1": "Index_R", "RThumb": "Thumb_R",
}
SIX = ("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation")


def renamed(m: Motion) -> Motion:
    """(a) The clip with other joint names."""
    return m.replace(skeleton=dataclasses.replace(m.skeleton, names=tuple(STUDIO[n] for n in m.skeleton.names)))


def static_root(m: Motion) -> Motion:
    """(b) A static joint 0 at the origin above the pelvis; 6 channels on every joint.

    The pelvis (joint 1) carries the CMU root travel in ``translations``; every
    other joint's translation channels hold its offset on every frame.
    """
    sk = m.skeleton
    J = sk.n_joints
    parents = np.concatenate([[-1], sk.parents + 1])
    parents[1] = 0
    offsets = np.concatenate([np.zeros((1, 3)), sk.offsets])
    new = Skeleton(
        ("joint_Root",) + sk.names, parents, offsets, channels=(SIX,) * (J + 1),
        end_site_parents=sk.end_site_parents + 1, end_site_offsets=sk.end_site_offsets,
    )
    F = m.n_frames
    rot = np.concatenate([np.tile([0.0, 0.0, 0.0, 1.0], (F, 1, 1)), m.rotations], axis=1)
    tr = np.array(np.broadcast_to(offsets, (F, J + 1, 3)))
    tr[:, 1] = m.root_positions
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # "the motion path follows joint 'Hips'"
        return Motion(new, rot, np.zeros((F, 3)), m.fps, translations=tr, name=m.name)


def cmu_columns(sm, layout: str) -> list[int]:
    """Variable indices of ``sm`` in the order of the CMU clip's variables."""
    if layout == "cmu":
        return list(range(sm.n_variables))
    if layout == "renamed":
        return [sm.variable_index("root_position")] + [sm.variable_index(STUDIO[n]) for n in CMU_NAMES]
    return [sm.variable_index("Hips.position")] + [sm.variable_index(n) for n in CMU_NAMES]


def joints_of(m: Motion, layout: str) -> slice:
    """The CMU joints among ``m``'s joints (all but the static joint 0 of layout b)."""
    return slice(1, None) if layout == "static" else slice(None)


CMU_NAMES: tuple[str, ...] = tuple(STUDIO)
LAYOUTS = ("cmu", "renamed", "static")


@pytest.fixture(scope="module", params=["16_15", "05_02"])
def clips(request, cmu):
    """The three layouts of a 3 s slice, each with its staggered poses (constraint layer on)."""
    m = cmu(request.param)[:360]
    assert m.skeleton.names == CMU_NAMES
    out = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        for layout, motion in zip(LAYOUTS, (m, renamed(m), static_root(m)), strict=True):
            out[layout] = (motion, extract(motion, max_poses=12, optimize=False, constraints=True))
    return out


def positions(m: Motion, layout: str) -> np.ndarray:
    return m.global_positions()[:, joints_of(m, layout)]


def test_layouts_have_the_same_roles(clips) -> None:
    (_, sm), (mb, smb) = clips["cmu"], clips["static"]
    # the static joint 0 is not the pelvis: the pelvis is found from the roles, not the hierarchy
    assert mb.skeleton.roles["pelvis"] == "Hips" and mb.skeleton.names[0] == "joint_Root"
    assert smb.translation_joints == (1,) and smb.variables[-1] == "Hips.position"
    assert smb.n_variables == sm.n_variables + 2  # joint_Root's rotation and the pelvis translation
    assert np.array_equal(smb.rest_translations, mb.translations[0])
    assert sm.translation_joints == () and sm.rest_translations is None


def test_extraction_finds_the_same_poses_and_refinements(clips) -> None:
    _, sm = clips["cmu"]
    for layout in ("renamed", "static"):
        _, other = clips[layout]
        assert np.array_equal(other.times, sm.times), layout
        assert np.array_equal(other.refinements[:, cmu_columns(other, layout)], sm.refinements), layout
        assert np.allclose(other.priorities, sm.priorities, rtol=1e-12, equal_nan=True)
    # the poses are refined (the comparison is not between empty refinements)
    assert np.count_nonzero(sm.refinements) > 50
    # the static joint 0 never moves: no refinements on its variables
    _, smb = clips["static"]
    assert np.all(smb.refinements[:, [0, 1]] == 0.0)


def test_unedited_clips_round_trip_translations_included(clips) -> None:
    for layout in LAYOUTS:
        m, sm = clips[layout]
        out = sm.evaluate()
        assert quat.angle(quat.mul(quat.inv(out.rotations), m.rotations)).max() < 1e-9, layout
        assert np.abs(out.global_positions() - m.global_positions()).max() < 1e-9, layout
        if m.translations is None:
            assert out.translations is None
        else:
            assert out.translations is not None and np.abs(out.translations - m.translations).max() < 1e-12


@pytest.mark.parametrize(
    "edit",
    [
        pytest.param(lambda sm: exaggerate(sm, 0.5), id="exaggerate"),
        pytest.param(lambda sm: succession(sm, 0.02, 2.0), id="succession"),
        pytest.param(lambda sm: succession(exaggerate(sm, 0.5, reference="previous"), 0.01, 1.0), id="both"),
        pytest.param(lambda sm: retime(sm, 5, float(sm.times[5] + 0.05)), id="retime"),
    ],
)
def test_edits_give_the_same_joint_positions(clips, edit) -> None:
    m, sm = clips["cmu"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StaggeredTimingWarning)
        ref = edit(sm).evaluate(constraints=False)
        assert np.abs(positions(ref, "cmu") - positions(m, "cmu")).max() > 0.01  # a real edit
        for layout in ("renamed", "static"):
            _, other = clips[layout]
            got = edit(other).evaluate(constraints=False)
            assert got.n_frames == ref.n_frames
            assert np.abs(positions(got, layout) - positions(ref, "cmu")).max() < 1e-6, layout


def test_the_constraint_layer_gives_the_same_result(clips) -> None:
    m, sm = clips["cmu"]
    names = sm.skeleton.roles.foot_joints()
    assert sm.constraints.joints == names
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StaggeredTimingWarning)
        edited = succession(exaggerate(sm, 0.5), 0.01, 1.0)
        ref = edited.evaluate()
        free = edited.evaluate(constraints=False)
        w, targets = sm.constraints.weights_and_targets(edited, ref.times, motion=free)
        feet = [m.skeleton.index(n) for n in names]
        on = w == 1.0
        # the layer acts: without it the planted feet leave their targets by centimetres
        err_free = np.linalg.norm(free.global_positions()[:, feet] - targets, axis=-1)[on].max()
        err_held = np.linalg.norm(ref.global_positions()[:, feet] - targets, axis=-1)[on].max()
        assert err_free > 0.02 and err_held < 0.005
        for layout in ("renamed", "static"):
            mo, other = clips[layout]
            assert other.constraints.joints == mo.skeleton.roles.foot_joints()
            got = succession(exaggerate(other, 0.5), 0.01, 1.0).evaluate()
            assert np.abs(positions(got, layout) - positions(ref, "cmu")).max() < 1e-6, layout


def test_retiming_keeps_the_travel_below_a_static_root(clips) -> None:
    (_, sm), (mb, smb) = clips["cmu"], clips["static"]
    longer = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StaggeredTimingWarning)
        for layout, s in (("cmu", sm), ("static", smb)):
            # a longer clip (without the constraint layer, which may lower the root where a stretched leg cannot reach)
            longer[layout] = retime(s, s.n_poses - 1, float(s.times[-1] + 0.25)).evaluate(constraints=False)
    out = longer["static"]
    assert out.n_frames > mb.n_frames and out.translations is not None
    pelvis = out.global_positions()[:, 1]
    # the pelvis travels as in the retimed CMU clip, and still ends where the capture ends
    assert np.abs(pelvis - longer["cmu"].root_positions).max() < 1e-9
    assert np.abs(pelvis[-1] - mb.translations[-1, 1]).max() < 1e-9
    assert np.linalg.norm(np.diff(mb.translations[:, 1], axis=0), axis=-1).sum() > 0.1
    # joint 0 stays put and the constant channels keep their values on every frame
    assert np.all(out.root_positions == 0.0)
    assert np.array_equal(out.translations[:, 2:], np.broadcast_to(mb.translations[0, 2:], out.translations[:, 2:].shape))


def test_translation_channels_varying_by_float_noise_are_constant(cmu) -> None:
    """Issue 25: channels that move by 1e-12 to 1e-7 m (an exporter's float noise) are no control variables."""
    m = static_root(cmu("16_15")[:240])
    tr = np.array(m.translations)
    rng = np.random.default_rng(3)
    noise = {5: 1e-12, 9: 1e-9, 14: 1e-7}  # joint: amplitude (m)
    for j, a in noise.items():
        tr[:, j] += rng.uniform(-a, a, size=(tr.shape[0], 3))
    tr[:, 20] += np.linspace(0.0, 0.02, tr.shape[0])[:, None]  # a joint that really slides, 2 cm
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        noisy = m.replace(translations=tr)
        sm = extract(noisy, max_poses=8, optimize=False)
    assert sm.translation_joints == (1, 20)  # the pelvis' travel and the slide; the noisy channels are constant
    assert np.array_equal(sm.rest_translations, tr[0])
    out = sm.evaluate()
    assert np.abs(out.translations - tr).max() < 2e-7  # within the noise: each channel at its first frame
    assert np.abs(out.global_positions() - noisy.global_positions()).max() < 1e-6


def test_every_joint_translated(cmu) -> None:
    """A clip whose translation channels all move: every one is a variable, and reproduced."""
    m = static_root(cmu("16_15")[:240])
    rng = np.random.default_rng(5)
    tr = np.array(m.translations)
    tr[:, 1:] += np.cumsum(rng.normal(scale=2e-4, size=tr[:, 1:].shape), axis=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        noisy = m.replace(translations=tr)
        sm = extract(noisy, max_poses=8, optimize=False)
    J = m.n_joints
    assert sm.translation_joints == tuple(range(1, J)) and sm.n_variables == 2 * J
    assert np.abs(sm.evaluate().translations - tr).max() < 1e-12
    assert np.abs(sm.evaluate().global_positions() - noisy.global_positions()).max() < 1e-9
    # inserting and deleting poses leave the motion unchanged; editing a translation moves that joint
    T = sm.knot_times
    ins = insert_pose(sm, float(0.5 * (np.nanmax(T[3]) + np.nanmin(T[4]))))
    assert np.abs(ins.evaluate().translations - tr).max() < 1e-9
    assert np.abs(delete_pose(sm, 3).evaluate().translations - tr).max() < 1e-9
    head = noisy.skeleton.index("Head")
    k = 4
    i = sm.variable_index("Head.position")
    target = sm.translation_values[k, i - J - 1] + [0.0, 0.05, 0.0]
    edited = edit_pose(sm, k, translations={"Head": target})
    assert np.allclose(edited.translation_values[k, i - J - 1], target)
    f = int(round((sm.times[k] + sm.refinements[k, i]) * sm.fps))
    assert np.abs(edited.evaluate().translations[f, head] - target).max() < 1e-9
    with pytest.raises(ValueError, match="translation variable"):
        edit_pose(sm, k, translations={"joint_Root": [0.0, 0.0, 0.0]})
    # a joint's translation is retimed with its rotation: the same depth below the chosen joint
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StaggeredTimingWarning)
        moved = succession(sm, 0.004, 1.0).refinements - sm.refinements
    d = succession_depths(sm.skeleton, translation_joints=sm.translation_joints)
    for name in ("Head", "LeftHand", "RightToeBase"):
        i, j = sm.variable_index(name + ".position"), sm.variable_index(name)
        assert d[i] == d[j] >= 4
        shift = moved[1:-1, i]  # s d(i)^l, but for knots stopped a frame short of a neighbour
        assert np.mean(np.isclose(shift, 0.004 * d[i])) > 0.5 and np.all(np.abs(shift) <= 0.004 * d[i] + 1e-12)


def test_constant_channels_are_kept_when_they_differ_from_the_offsets(cmu) -> None:
    """Translation channels, not the skeleton offsets, place the joints: constant ones are kept as they are."""
    m = static_root(cmu("16_15")[:240])
    short = m.replace(skeleton=m.skeleton.scaled(0.5))  # offsets that the channels override
    assert np.abs(short.global_positions() - m.global_positions()).max() < 1e-12
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        sm = extract(short, max_poses=8, optimize=False)
    assert sm.translation_joints == (1,)
    out = sm.evaluate()
    assert np.abs(out.global_positions() - m.global_positions()).max() < 1e-9
    assert np.array_equal(out.translations[:, 2:], m.translations[:, 2:])
    assert np.abs(sm.pose_motion(3).global_positions()[0, 2:] - sm.evaluate(sm.times[3:4]).global_positions()[0, 2:]).max() < 1e-9


def test_role_overrides_reach_every_default(cmu) -> None:
    walk = cmu("16_15")[:360]
    r = walk.skeleton.roles
    # plant the balls of the feet instead of the ankles: a user's choice the roles carry
    over = {"left_ankle": r["left_toe"], "right_ankle": r["right_toe"]}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        sm = extract(walk, max_poses=10, optimize=False, constraints=True, roles=over)
        plain = extract(walk, max_poses=10, optimize=False, constraints=True)
    assert sm.constraints.joints == (r["left_toe"], r["right_toe"])
    assert plain.constraints.joints == r.foot_joints()
    assert sm.skeleton.roles["left_ankle"] == r["left_toe"]  # kept for later edits
    ed = StaggeredEditor(walk, max_poses=6, optimize=False, roles=over)
    assert ed.analysis.event_joints == (r["left_toe"], r["right_toe"])
    # the succession's default joint is the pelvis role
    assert default_joint(walk.skeleton) == r["pelvis"]
    assert default_joint(walk.skeleton, {"pelvis": r["spine"][0]}) == r["spine"][0]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StaggeredTimingWarning)
        moved = succession(plain, 0.01, 1.0, roles={"pelvis": r["spine"][0]}).refinements - plain.refinements
    legs = [plain.variable_index(r[f"{s}_knee"]) for s in ("left", "right")]
    arms = [plain.variable_index(r[f"{s}_elbow"]) for s in ("left", "right")]
    assert np.all(moved[:, legs] == 0.0) and np.all(moved[1:-1, arms] != 0.0)
