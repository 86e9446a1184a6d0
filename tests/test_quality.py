"""mocaplab.quality on hand-made motions with known answers, and invariance on real clips."""

from __future__ import annotations

import numpy as np
import pytest

from mocaplab import Motion, Skeleton, quality, quat
from mocaplab.contacts import Contacts, estimate_floor

FPS = 30.0
FEET = ("LeftFoot", "LeftToeBase", "RightFoot", "RightToeBase")


def biped() -> Skeleton:
    """A small human facing +z, Y up (left is +x): legs, spine, head, arms out sideways."""
    names, parents, offsets = ["Hips"], [-1], [[0, 0, 0]]

    def add(name, parent, offset):
        names.append(name)
        parents.append(names.index(parent))
        offsets.append(offset)

    for side, s in (("Left", 1.0), ("Right", -1.0)):
        add(f"{side}UpLeg", "Hips", [0.1 * s, 0, 0])
        add(f"{side}Leg", f"{side}UpLeg", [0, -0.45, 0])
        add(f"{side}Foot", f"{side}Leg", [0, -0.42, 0])
        add(f"{side}ToeBase", f"{side}Foot", [0, -0.06, 0.12])
    add("Spine", "Hips", [0, 0.1, 0])
    add("Spine1", "Spine", [0, 0.2, 0])
    add("Neck", "Spine1", [0, 0.22, 0])
    add("Head", "Neck", [0, 0.1, 0])
    for side, s in (("Left", 1.0), ("Right", -1.0)):
        add(f"{side}Shoulder", "Spine1", [0.05 * s, 0.18, 0])
        add(f"{side}Arm", f"{side}Shoulder", [0.12 * s, 0, 0])
        add(f"{side}ForeArm", f"{side}Arm", [0.28 * s, 0, 0])
        add(f"{side}Hand", f"{side}ForeArm", [0.25 * s, 0, 0])
    ends = [names.index(n) for n in ("LeftToeBase", "RightToeBase", "Head", "LeftHand", "RightHand")]
    end_offsets = [[0, 0, 0.06], [0, 0, 0.06], [0, 0.15, 0], [0.08, 0, 0], [-0.08, 0, 0]]
    return Skeleton(names, parents, offsets, end_site_parents=ends, end_site_offsets=end_offsets)


def pose(n: int = 40, *, knee_deg=25.0, elbow_deg=30.0, root=None, fps: float = FPS) -> Motion:
    """``n`` frames of the biped, knees bent by ``knee_deg`` (scalar or per frame, per side), elbows too."""
    sk = biped()
    rot = np.tile([0.0, 0.0, 0.0, 1.0], (n, sk.n_joints, 1))
    knee = np.broadcast_to(np.asarray(knee_deg, dtype=float), (n,) if np.ndim(knee_deg) < 2 else np.shape(knee_deg))
    for k, side in enumerate(("Left", "Right")):
        angle = np.radians(knee if knee.ndim == 1 else knee[:, k])
        rot[:, sk.index(f"{side}Leg")] = quat.from_axis_angle([1.0, 0.0, 0.0], angle)
        rot[:, sk.index(f"{side}UpLeg")] = quat.from_axis_angle([1.0, 0.0, 0.0], -0.5 * angle)
        rot[:, sk.index(f"{side}Foot")] = quat.from_axis_angle([1.0, 0.0, 0.0], -0.5 * angle)
        s = 1.0 if side == "Left" else -1.0
        rot[:, sk.index(f"{side}ForeArm")] = quat.from_axis_angle([0.0, s, 0.0], -np.radians(elbow_deg) * np.ones(n))
    if root is None:
        root = np.tile([0.0, 0.92, 0.0], (n, 1))
    return Motion(sk, rot, root, fps, name="biped")


def planted(motion: Motion) -> Contacts:
    return Contacts(FEET, np.ones((motion.n_frames, len(FEET)), dtype=bool), motion.fps)


# ----------------------------------------------------------------- known answers
def test_a_foot_sliding_one_centimetre_per_frame_skates_ten_millimetres_per_frame():
    still = pose()
    root = np.array(still.root_positions)
    root[:, 0] += 0.01 * np.arange(still.n_frames)
    sliding = still.replace(root_positions=root)
    assert quality.measure(still, contacts=planted(still))["skate"].value == pytest.approx(0.0, abs=1e-9)
    assert quality.measure(sliding, contacts=planted(sliding))["skate"].value == pytest.approx(10.0, rel=1e-9)
    row = quality.compare(still, sliding, contacts=planted(still))["skate"]
    assert row.before == pytest.approx(0.0, abs=1e-9) and row.after == pytest.approx(10.0)
    assert row.regressed and row.ratio == np.inf


def test_skate_counts_only_frames_planted_in_the_input():
    still = pose()
    root = np.array(still.root_positions)
    root[20:, 0] += 0.02 * np.arange(1, still.n_frames - 19)  # slides from frame 20 on
    sliding = still.replace(root_positions=root)
    mask = np.zeros((still.n_frames, 4), dtype=bool)
    mask[:20] = True  # planted only before the slide: nothing to count
    early = Contacts(FEET, mask, FPS)
    assert quality.compare(still, sliding, contacts=early)["skate"].after == pytest.approx(0.0, abs=1e-9)
    mask[:] = False
    mask[25:35] = True
    late = Contacts(FEET, mask, FPS)
    assert quality.compare(still, sliding, contacts=late)["skate"].after == pytest.approx(20.0)


def test_skate_per_second_is_the_same_at_any_frame_rate():
    # a foot sliding at 0.3 m/s: 10 mm per frame at 30 fps, 2.5 at 120 fps
    for fps, expected in ((30.0, 10.0), (120.0, 2.5)):
        n = int(fps)
        root = np.tile([0.0, 0.92, 0.0], (n, 1))
        root[:, 0] = 0.3 * np.arange(n) / fps
        m = pose(n, root=root, fps=fps)
        assert quality.measure(m, contacts=planted(m))["skate"].value == pytest.approx(expected)


def test_a_joint_that_jumps_five_centimetres_in_one_frame_is_a_pop():
    still = pose()
    root = np.array(still.root_positions)
    root[20:, 0] += 0.05
    popped = still.replace(root_positions=root)
    row = quality.compare(still, popped, contacts=None)["displacement"]
    assert row.after == pytest.approx(50.0) and row.before == pytest.approx(0.0, abs=1e-9)
    assert row.regressed and row.where in popped.skeleton.names
    assert quality.measure(popped, contacts=None)["displacement"].value == pytest.approx(50.0)


def test_one_frame_turn_of_a_joint_gives_its_angular_acceleration():
    still = pose()
    rot = np.array(still.rotations)
    j = still.skeleton.index("LeftArm")
    rot[20:, j] = quat.from_axis_angle([0.0, 0.0, 1.0], 0.1)  # a 0.1 rad step at frame 20
    turned = still.replace(rotations=rot)
    acc = quality.angular_acceleration(turned)
    assert acc[j] == pytest.approx(0.1 * FPS**2, rel=1e-6)  # 90 rad/s^2: 0.1 rad in one frame, then still
    assert np.delete(acc, j).max() == pytest.approx(0.0, abs=1e-6)
    row = quality.compare(still, turned, contacts=None)["angular_acceleration"]
    assert row.where == "LeftArm" and row.regressed


def test_a_knee_that_bends_the_other_way_is_a_flip():
    n = 40
    knees = np.tile(25.0 + 10.0 * np.sin(np.linspace(0, 3, n))[:, None], (1, 2))
    before = pose(n, knee_deg=knees)
    flipped = knees.copy()
    flipped[20:30, 0] *= -1.0  # the left knee bends forwards for 10 frames
    after = pose(n, knee_deg=flipped)
    assert quality.hinge_flips(before) == {"left_knee": 0, "right_knee": 0, "left_elbow": 0, "right_elbow": 0}
    flips = quality.hinge_flips(after, quality.hinge_axes(before))
    assert flips["left_knee"] == 10 and flips["right_knee"] == 0
    row = quality.compare(before, after, contacts=None)["hinge_flips"]
    assert row.after == 10 and row.before == 0 and row.regressed and row.where == "left_knee"


def test_a_straight_knee_is_never_a_flip():
    before = pose(knee_deg=25.0)
    straight = pose(knee_deg=np.where(np.arange(40) < 20, 25.0, -5.0))  # 5 degrees the other way: straight
    assert quality.hinge_flips(straight, quality.hinge_axes(before))["left_knee"] == 0


def test_a_knee_bent_sideways_is_not_a_flip_but_bent_backwards_is():
    # the bend's component about the input's hinge counts: 20 degrees about an axis 91 degrees off the hinge
    # (-0.3 degrees about it) is not bent the other way; 20 degrees about one 150 degrees off (-17.3) is
    before = pose(knee_deg=25.0)
    sk = before.skeleton
    knee = sk.index("LeftLeg")
    for off, flips in ((91.0, 0), (150.0, 40)):
        rot = np.array(before.rotations)
        axis = [np.cos(np.radians(off)), 0.0, np.sin(np.radians(off))]  # the hinge is +x; the bone runs along -y
        rot[:, knee] = quat.from_axis_angle(axis, np.radians(20.0) * np.ones(before.n_frames))
        bent = before.replace(rotations=rot)
        assert quality.hinge_flips(bent, quality.hinge_axes(before))["left_knee"] == flips, off


def test_feet_pushed_three_centimetres_under_the_floor():
    still = pose()
    root = np.array(still.root_positions)
    root[10:20, 1] -= 0.03
    sunk = still.replace(root_positions=root)
    row = quality.compare(still, sunk, contacts=planted(still))["penetration"]
    assert row.before == pytest.approx(0.0, abs=1e-9) and row.after == pytest.approx(30.0)
    assert row.regressed


def test_the_floor_is_the_one_the_feet_stand_on_level_lifted_or_sloped():
    still = pose()
    floor = estimate_floor(still, planted(still))
    assert floor.angle == pytest.approx(0.0, abs=1e-9)
    # the same clip half a metre up: the same planted heights above its own floor
    up = estimate_floor(still.replace(root_positions=still.root_positions + [0, 0.5, 0]), planted(still))
    np.testing.assert_allclose(up.levels - floor.levels, 0.5, atol=1e-12)
    # walking 3 m up a 10-degree slope: the floor's slope is found along the walk
    n = 60
    x = np.linspace(0.0, 3.0, n)
    root = np.column_stack([np.zeros(n), 0.92 + np.tan(np.radians(10.0)) * x, x])
    uphill = pose(n, root=root)
    slope = estimate_floor(uphill, planted(uphill))
    assert slope.angle == pytest.approx(10.0, abs=1e-6)
    assert quality.measure(uphill, contacts=planted(uphill))["penetration"].value == pytest.approx(0.0, abs=1e-6)


def test_bones_that_stretch_drift():
    still = pose()
    sk = still.skeleton
    tr = np.tile(sk.offsets, (still.n_frames, 1, 1))
    j = sk.index("LeftLeg")
    tr[:, j] *= 1.02  # the thigh 2 % longer: 9 mm
    stretched = still.replace(translations=tr)
    row = quality.compare(still, stretched, contacts=None)["bone_drift"]
    assert row.after == pytest.approx(9.0) and row.where == "LeftLeg" and row.regressed
    assert quality.measure(stretched, contacts=None)["bone_drift"].value == pytest.approx(0.0, abs=1e-9)


def test_an_unchanged_motion_regresses_nothing():
    before = pose(knee_deg=25.0 + 10.0 * np.sin(np.linspace(0, 3, 40)))
    report = quality.compare(before, before, contacts=planted(before))
    assert report.ok and not report.regressions
    for row in report:
        assert row.after == row.before or (np.isnan(row.after) and np.isnan(row.before)), row


def test_limits_decide_what_regresses():
    still = pose()
    root = np.array(still.root_positions)
    root[20:, 0] += 0.005
    nudged = still.replace(root_positions=root)  # a 5 mm pop
    assert not quality.compare(still, nudged, contacts=None, limits={"displacement": quality.Limit(1.5, 10.0)})[
        "displacement"
    ].regressed
    assert quality.compare(still, nudged, contacts=None, limits={"displacement": quality.Limit(1.5, 2.0)})[
        "displacement"
    ].regressed
    with pytest.raises(ValueError, match="Unknown measures in `limits`: \\['wobble'\\]"):
        quality.compare(still, nudged, limits={"wobble": quality.Limit(1, 0)})


def test_bad_arguments_are_named():
    m = pose()
    with pytest.raises(TypeError, match="`before` to be a Motion"):
        quality.compare("walk.bvh", m)
    with pytest.raises(TypeError, match="`contacts` to be 'auto', None or a Contacts"):
        quality.measure(m, contacts="yes")
    with pytest.raises(ValueError, match="contacts. over 40 frames, got 10"):
        quality.measure(m, contacts=Contacts(FEET, np.ones((10, 4), bool), FPS))
    other = Motion(Skeleton(["Hips"], [-1], [[0, 0, 0]]), np.tile([0, 0, 0, 1.0], (40, 1, 1)), np.zeros((40, 3)), FPS)
    with pytest.raises(ValueError, match="lacks"):
        quality.compare(m, other)


def test_reports_print_a_table_and_escape_names_in_html():
    m = pose().replace(name="<script>alert(1)</script>")
    report = quality.compare(m, m, contacts=planted(m))
    text = repr(report)
    assert "skate" in text and "penetration" in text and "no regression" in text
    page = report._repr_html_()
    assert "<script>" not in page and "&lt;script&gt;" in page
    assert "<script>" not in quality.measure(m)._repr_html_()


def test_inputs_are_not_mutated():
    m = pose()
    before = [a.copy() for a in (m.rotations, m.root_positions)]
    quality.compare(m, m)
    np.testing.assert_array_equal(m.rotations, before[0])
    np.testing.assert_array_equal(m.root_positions, before[1])


def test_a_skeleton_without_feet_reports_why():
    sk = Skeleton(["base", "arm", "tip"], [-1, 0, 1], [[0, 0, 0], [0, 1, 0], [0, 1, 0]])
    m = Motion(sk, np.tile([0, 0, 0, 1.0], (10, 3, 1)), np.zeros((10, 3)), FPS)
    q = quality.measure(m)
    assert np.isnan(q["skate"].value) and "no feet" in q["skate"].note
    assert np.isnan(q["hinge_flips"].value)


# ----------------------------------------------------------------- real clips
def test_real_walk_against_itself_and_a_pushed_down_copy(cmu):
    walk = cmu("16_15")
    same = quality.compare(walk, walk)
    assert same.ok
    assert same["skate"].before == pytest.approx(same["skate"].after)
    assert 0.3 < same["skate"].before < 5.0, "a captured walk skates a little"
    assert 1.0 < same["zmp"].before < 60.0
    sunk = walk.replace(root_positions=walk.root_positions - [0, 0.04, 0])
    assert quality.compare(walk, sunk)["penetration"].after > 35.0


@pytest.mark.parametrize("convention", ["mixamo", "game_studio", "centimetres", "z_up", "asf_names"])
def test_the_same_walk_in_another_convention_measures_the_same(cmu, converted, convention):
    walk = cmu("16_15")[0:360]
    other, name_map = converted("16_15", convention)
    a, b = quality.measure(walk), quality.measure(other)
    for name in ("skate", "skate_max", "penetration", "zmp", "hinge_flips"):
        assert b[name].value == pytest.approx(a[name].value, rel=1e-3, abs=1e-3), name
    assert b["displacement"].value == pytest.approx(a["displacement"].value, rel=1e-3)
    assert b["displacement"].where == name_map[a["displacement"].where]


def test_the_same_edit_at_another_frame_rate_gives_the_same_ratios(cmu):
    walk = cmu("16_15")[0:360]
    sunk = walk.replace(root_positions=walk.root_positions - [0, 0.03, 0])
    fine, coarse = quality.compare(walk, sunk), quality.compare(walk.resample(30), sunk.resample(30))
    assert coarse["penetration"].after - coarse["penetration"].before == pytest.approx(
        fine["penetration"].after - fine["penetration"].before, abs=3.0
    )
    assert coarse["zmp"].ratio == pytest.approx(fine["zmp"].ratio, rel=0.2)


def test_a_static_root_that_moves_is_reported(converted):
    studio, _ = converted("16_15", "game_studio")
    assert quality.measure(studio)["static_root"].value == 0.0
    assert quality.measure(studio)["bone_drift"].value < 1.0, "the pelvis translating below the root is no bone"
    moved = studio.transformed(translation=[0.3, 0.0, 0.0])  # moves the pelvis below the static root
    assert quality.compare(studio, moved)["static_root"].after == pytest.approx(0.0, abs=1e-6)
    broken = studio.replace(root_positions=studio.root_positions + [0.1, 0.0, 0.0])
    row = quality.compare(studio, broken)["static_root"]
    assert row.after == pytest.approx(100.0) and row.regressed
