"""Physical touch-up (Shin et al. 2003 s3.3-3.4): invariants, closed forms, CMU claims."""

from __future__ import annotations

import numpy as np
import pytest
from test_physics_body import LAYOUTS

from mocaplab import quat
from mocaplab.contacts import foot_contacts
from mocaplab.physics import (
    FLIGHT_SCHEDULE,
    GROUND_SCHEDULE,
    Adjustment,
    Body,
    TouchUpSession,
    angular_momentum,
    balance,
    center_of_mass,
    default_schedule,
    flight_stages,
    link_sets,
    preset_mask,
    start,
    step,
    touch_up,
)
from mocaplab.physics.touchup import _ground_rotation
from mocaplab.physics.zmp import zmp_from_links


@pytest.fixture(scope="module")
def walk30(mocap_dir):
    from mocaplab import data

    return data.cmu("16_15").resample(30)


def bend(motion, radius):
    """Turn a straight walk into an arc: rotate the root's heading with the distance walked."""
    p = motion.root_positions
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p[:, [0, 2]], axis=0), axis=1))])
    q = quat.from_yaw(s / radius)
    step_xz = np.diff(p, axis=0) * [1.0, 0.0, 1.0]
    new = np.array(p)
    new[1:, [0, 2]] = p[0, [0, 2]] + np.cumsum(quat.rotate(q[:-1], step_xz)[:, [0, 2]], axis=0)
    return motion.with_root(root_positions=new, root_rotations=quat.mul(q, motion.rotations[:, 0]))


def inward_lean_degrees(motion):
    """Mean tilt of the hips-to-neck line toward the side the path turns to."""
    g = motion.global_positions()
    up = g[:, motion.skeleton.index("Neck")] - g[:, 0]
    d = np.gradient(motion.root_positions, axis=0) * [1.0, 0.0, 1.0]
    inward = np.cross([0.0, 1.0, 0.0], d / np.linalg.norm(d, axis=1, keepdims=True))
    return float(np.degrees(np.arctan2(np.sum(up * inward, axis=1), up[:, 1])).mean())


# ------------------------------------------------------------------ schedules
def test_default_schedules_are_the_papers():
    assert [a.rho for a in GROUND_SCHEDULE] == [0.5, 0.3, 0.2]
    assert [round(a.width(30.0)) for a in GROUND_SCHEDULE] == [40, 20, 10]
    assert [round(a.width(120.0)) for a in GROUND_SCHEDULE] == [160, 80, 40]
    assert [a.rho for a in FLIGHT_SCHEDULE] == [0.3, 0.3, 1.0]
    assert [round(a.width(30.0)) for a in FLIGHT_SCHEDULE] == [10, 10, 5]
    assert GROUND_SCHEDULE[0].s2 == ("lower_body",) and GROUND_SCHEDULE[0].s3 == ("upper_body",)
    assert default_schedule("both") == GROUND_SCHEDULE + FLIGHT_SCHEDULE


def test_adjustment_validation():
    with pytest.raises(ValueError, match="rho"):
        Adjustment(("arms",), rho=0.0)
    with pytest.raises(ValueError, match="s3"):
        Adjustment(("all",), ("arms",), stage="flight")
    with pytest.raises(ValueError, match="stage"):
        Adjustment(("all",), stage="air")  # type: ignore[arg-type]
    a = Adjustment("arms", rho=0.2)
    assert a.s2 == ("arms",)
    assert a.replace(rho=0.4).label == a.label
    assert a.replace(s2=("upper_body",)).label != a.label


def test_presets_on_the_cmu_skeleton(walk30):
    sk = walk30.skeleton
    upper = preset_mask(sk, "upper_body")
    assert upper.sum() == 20 and upper[sk.index("LowerBack")] and not upper[0]
    assert (preset_mask(sk, "lower_body") == ~upper).all()
    arms = preset_mask(sk, "arms")
    assert arms.sum() == 12 and arms[sk.index("RThumb")] and not arms[sk.index("LeftShoulder")]
    assert preset_mask(sk, "LeftLeg").sum() == 3
    with pytest.raises(KeyError, match="preset"):
        preset_mask(sk, "tail")


def test_presets_follow_the_roles(cmu, walk30):
    sk = walk30.skeleton
    # the user says the CMU "LeftShoulder" joints are the upper arms: the arms preset grows by them
    arms = preset_mask(sk, "arms", roles={"left_shoulder": "LeftShoulder", "right_shoulder": "RightShoulder"})
    assert arms.sum() == 14 and arms[sk.index("LeftShoulder")] and not arms[sk.index("Spine1")]
    state = start(walk30[:40], roles={"left_shoulder": "LeftShoulder", "right_shoulder": "RightShoulder"})
    assert link_sets(sk, GROUND_SCHEDULE[2], roles=state.roles).s2_tops == (sk.index("LeftShoulder"), sk.index("RightShoulder"))
    # the Daz skeleton: the upper body is the abdomen's subtree, the arms hang from the upper arms
    salsa = cmu("60_10").skeleton
    upper = preset_mask(salsa, "upper_body")
    assert upper[salsa.index("abdomen")] and not upper[salsa.index("hip")] and not upper[salsa.index("lThigh")]
    assert upper.sum() == 34
    assert link_sets(salsa, GROUND_SCHEDULE[2]).s2_tops == (salsa.index("rShldr"), salsa.index("lShldr"))
    # a skeleton without arms says what is missing
    from mocaplab.motion import Skeleton
    from mocaplab.roles import RolesError

    stick = Skeleton(["Hips", "LeftUpLeg", "LeftLeg", "LeftFoot", "RightUpLeg", "RightLeg", "RightFoot", "Spine", "Neck", "Head"],
                     [-1, 0, 1, 2, 0, 4, 5, 0, 7, 8],
                     [[0, 1, 0], [0.1, 0, 0], [0, -0.45, 0], [0, -0.45, 0], [-0.1, 0, 0], [0, -0.45, 0], [0, -0.45, 0],
                      [0, 0.2, 0], [0, 0.3, 0], [0, 0.1, 0]])
    assert preset_mask(stick, "upper_body").sum() == 3
    with pytest.raises(RolesError, match="left_shoulder.*'arms' preset"):
        preset_mask(stick, "arms")


def test_link_sets_shapes(walk30):
    sk = walk30.skeleton
    sets = link_sets(sk, GROUND_SCHEDULE[0])
    assert sets.s2_tops == (0,)
    assert sets.carried == ((sk.index("LowerBack"), 0),)
    arms = link_sets(sk, GROUND_SCHEDULE[2])
    assert arms.s2_tops == (sk.index("LeftArm"), sk.index("RightArm"))
    with pytest.raises(ValueError, match="S3 must hang below S2"):
        link_sets(sk, Adjustment(("arms",), ("LeftUpLeg",)))
    with pytest.raises(ValueError, match="empty"):
        link_sets(sk, Adjustment(("Neck",), ("upper_body",)))


# ------------------------------------------------------------- closed forms
def test_ground_rotation_puts_the_zmp_on_its_projection(walk30):
    """Equations 6-7: with accelerations frozen, the rotated links put the ZMP on Z'."""
    body = Body.from_skeleton(walk30)
    c = foot_contacts(walk30)
    bal = balance(walk30, body, contacts=c)
    for adj in GROUND_SCHEDULE:
        sets = link_sets(walk30.skeleton, adj)
        omega, centre = _ground_rotation(walk30, body, sets, bal, np.ones(walk30.n_frames))
        moved = np.linalg.norm(omega, axis=1) > 0
        assert moved.sum() > 10
        # rotate the smoothed link centres exactly as the adjustment would
        r = bal.positions.copy()
        gpos = walk30.global_positions()
        q = quat.exp(omega)
        for li, owner in enumerate(body.owners):
            role, part, top = sets.roles[owner], sets.part[owner], sets.carried_top[owner]
            if part < 0 or (role == 1 and top < 0):
                continue
            t = sets.s2_tops[part]
            piv = centre if t == 0 else gpos[:, t]
            if top >= 0:  # carried: translate with its boundary joint
                b = gpos[:, top]
                r[:, li] += piv + quat.rotate(q, b - piv) - b
            else:
                r[:, li] = piv + quat.rotate(q, r[:, li] - piv)
        z = zmp_from_links(r, bal.accelerations, body.masses)
        angle = np.linalg.norm(omega, axis=1)
        exact = moved & (angle < 0.34)  # not clamped by the 20-degree guard
        xa = (bal.projection - bal.zmp)[exact] * [1.0, 0.0, 1.0]
        xa /= np.linalg.norm(xa, axis=1, keepdims=True)
        miss = (z - bal.projection)[exact]
        along = np.abs(np.sum(miss * xa, axis=1))
        # equation 6 solved along the correction: exact unless the square root
        # was clamped (no rotation reaches Z'); the sideways change of Z_z is
        # neglected, as in the paper, and stays below a millimetre
        hit = along < 1e-9
        assert np.mean(hit) > 0.8, adj.label
        assert np.abs(miss[hit][:, [0, 2]]).max() < 1e-3, adj.label


def test_s3_keeps_its_global_orientation_and_s1_stays(walk30):
    body = Body.from_skeleton(walk30)
    sk = walk30.skeleton
    h = touch_up(walk30, body=body, schedule=GROUND_SCHEDULE[0], iterations=1, footplants=None)
    before, after = walk30.global_rotations(), h.final.global_rotations()
    upper = preset_mask(sk, "upper_body")
    d = quat.angle(quat.mul(quat.inv(before[:, upper]), after[:, upper]))
    assert d.max() < 1e-6
    lower_moved = quat.angle(quat.mul(quat.inv(before[:, 0]), after[:, 0]))
    assert lower_moved.max() > 1e-3
    h2 = touch_up(walk30, body=body, schedule=GROUND_SCHEDULE[1], iterations=1, footplants=None)
    lower = preset_mask(sk, "lower_body")
    assert np.allclose(h2.final.global_positions()[:, lower], walk30.global_positions()[:, lower], atol=1e-9)
    assert not np.allclose(h2.final.global_positions()[:, upper], walk30.global_positions()[:, upper], atol=1e-4)


# ------------------------------------------------------------ state, history
def test_kinematics_carried_along_match_forward_kinematics(cmu, walk30):
    jump = cmu("16_05").resample(30)
    for motion in (bend(walk30, 2.0), bend(jump, 1.0)):
        for fp in ("ik", "plant", None):
            state = start(motion, footplants=fp)
            for _ in range(6):
                state = step(state)
                grot, gpos = state.kinematics
                assert np.allclose(gpos, state.motion.global_positions(), atol=1e-10)
                same = np.abs(np.sum(grot * state.motion.global_rotations(), axis=-1))
                assert np.allclose(same, 1.0, atol=1e-10)


def test_touch_up_is_pure_and_records_every_step(walk30):
    rot, root = walk30.rotations.copy(), walk30.root_positions.copy()
    h = touch_up(walk30, iterations=2)
    assert np.array_equal(walk30.rotations, rot) and np.array_equal(walk30.root_positions, root)
    assert len(h) == len(h.motions) == 7
    assert h.motions[0] is walk30 and h.final is h.motions[-1]
    assert h.zmp_distance.shape == (7, walk30.n_frames)
    assert np.allclose(h.mean_zmp_distance, np.nanmean(h.zmp_distance, axis=1))
    assert h.labels[0] == "input" and h.labels[1] == GROUND_SCHEDULE[0].label
    assert all(np.all(np.isfinite(m.rotations)) for m in h.motions)
    assert len(touch_up(walk30, iterations=0)) == 1


def test_step_function_and_session_agree_with_touch_up(walk30):
    h = touch_up(walk30, iterations=1, footplants="ik")
    state = start(walk30, footplants="ik")
    for k in range(3):
        state = step(state)
        assert np.allclose(state.motion.rotations, h.motions[k + 1].rotations)
    s = TouchUpSession(walk30, footplants="ik")
    s.run(3)
    assert np.allclose(s.current.motion.rotations, h.final.rotations)
    s.back()
    first = s.back()
    assert first.index == 1 and s.index == 1
    s.forward()
    assert s.index == 2 and len(s.history) == 3
    s.set_adjustment(2, rho=0.6)
    assert s.schedule[2].rho == 0.6 and s.index == 2
    with pytest.raises(KeyError):
        s.set_adjustment(0, s2=("no_such_joint",))
    s.finish_pass()
    assert s.index == 3
    s.finish_pass()
    assert s.index == 6 and s.current.iteration == 2


def test_ik_footplants_put_planted_feet_back(walk30):
    """The "ik" goals: planted ankles and toes back where the input has them (the IK layer of refinement)."""
    from mocaplab.physics.touchup import _footplant_fn, _posed

    c = foot_contacts(walk30)
    bent = bend(walk30, 2.0)
    moved = touch_up(bent, contacts=c, schedule=GROUND_SCHEDULE[0], iterations=1, footplants=None).final
    fixed = _footplant_fn("ik", c, bent)(_posed(moved)).motion
    sk = walk30.skeleton
    for ankle, toe in (("LeftFoot", "LeftToeBase"), ("RightFoot", "RightToeBase")):
        planted = c.of(ankle) | c.of(toe)
        inner = planted & np.roll(planted, 8) & np.roll(planted, -8)  # well inside a plant (weight 1)
        for j in (sk.index(ankle), sk.index(toe)):
            before = np.linalg.norm(moved.global_positions()[inner, j] - bent.global_positions()[inner, j], axis=1)
            after = np.linalg.norm(fixed.global_positions()[inner, j] - bent.global_positions()[inner, j], axis=1)
            assert before.max() > 5e-4 and after.max() < 1e-6
        # the foot may keep a turn about its own axis (ankle to toe), no other
        j = sk.index(ankle)
        delta = quat.mul(fixed.global_rotations()[inner, j], quat.inv(bent.global_rotations()[inner, j]))
        axis = quat.log(delta)
        foot = bent.global_positions()[inner, sk.index(toe)] - bent.global_positions()[inner, j]
        across = np.linalg.norm(np.cross(axis, foot / np.linalg.norm(foot, axis=1, keepdims=True)), axis=1)
        assert across.max() < 1e-6
    # frames far from any plant are left alone
    free = ~np.convolve((c.of("LeftFoot") | c.of("LeftToeBase")).astype(float), np.ones(15), "same").astype(bool)
    j = sk.index("LeftFoot")
    assert free.any() and np.allclose(fixed.global_positions()[free, j], moved.global_positions()[free, j], atol=1e-12)


def test_options_are_validated(walk30):
    with pytest.raises(ValueError, match="iterations"):
        touch_up(walk30, iterations=-1)
    with pytest.raises(ValueError, match="footplants"):
        touch_up(walk30, footplants="glue")  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="Motion"):
        touch_up("walk")  # type: ignore[arg-type]
    seen = []

    def fix(m, contacts, reference):
        seen.append(reference)
        return m

    touch_up(walk30, iterations=1, footplants=fix)
    # only the first ground adjustment (lower body in S2) can move the feet
    assert len(seen) == 1 and seen[0] is walk30


@pytest.mark.filterwarnings("ignore::UserWarning")
@pytest.mark.parametrize("layout", sorted(LAYOUTS))
def test_touch_up_does_not_depend_on_names_or_a_static_root(cmu, layout):
    """A renamed skeleton, an unnamed one and a static joint 0 above the pelvis give the same touch-up."""
    convert, shift = LAYOUTS[layout]
    for clip, radius in (("16_15", 2.0), ("16_05", 1.0)):  # a walk (ground schedule), a jump (and flight)
        motion = bend(cmu(clip).resample(30)[:90], radius)
        other = convert(motion)
        h0, h1 = touch_up(motion, iterations=1), touch_up(other, iterations=1)  # no name given
        assert len(h1) == len(h0) and h1.labels == h0.labels
        assert np.allclose(h1.mean_zmp_distance, h0.mean_zmp_distance, atol=1e-6)
        for m0, m1 in zip(h0.motions[1:], h1.motions[1:], strict=True):
            g0, g1 = m0.global_positions(), m1.global_positions()[:, shift:]
            assert np.abs(g1 - g0).max() < 1e-3, (clip, m1)
        if layout == "static_root":  # the translation channels are carried through every step
            assert all(m.translations is not None and np.array_equal(m.translations, other.translations) for m in h1.motions)
        assert np.abs(h0.final.global_positions() - motion.global_positions()).max() > 0.01  # it did something


# ------------------------------------------------------------------- claims
def test_bent_walk_gains_an_inward_lean_and_balance(walk30):
    bent = bend(walk30, 2.0)
    c = foot_contacts(walk30)
    h = touch_up(bent, contacts=c, iterations=3)
    assert h.mean_zmp_distance[-1] <= 0.5 * h.mean_zmp_distance[0]
    assert inward_lean_degrees(h.final) > inward_lean_degrees(bent) + 1.5


@pytest.mark.parametrize("clip", ["16_15", "02_01"])
def test_captured_walk_changes_little(clip, cmu):
    walk = cmu(clip).resample(30)
    h = touch_up(walk, iterations=3)
    moved = np.linalg.norm(h.final.global_positions() - walk.global_positions(), axis=-1)
    assert moved.mean() < 0.02
    # the ends of the clip are no exception (02_01 starts as a foot lands
    # and ends as one takes off: badly balanced end frames must not lean
    # the whole start or end of the clip)
    per_frame = moved.mean(axis=1)
    assert per_frame[:10].mean() < 0.04 and per_frame[-10:].mean() < 0.04


def test_smoothing_weighs_end_frames_like_the_others():
    from mocaplab.physics.touchup import _smooth

    n, width = 60, 40.0
    spike = np.zeros((n, 3))
    spike[0] = 1.0
    out = _smooth(spike, width)
    assert np.allclose(_smooth(np.ones((n, 2)), width), 1.0)  # a constant stays
    inner = np.zeros((n, 3))
    inner[30] = 1.0
    # an end frame gets less than twice the weight of an inner frame (the
    # kernel is cut and renormalised: its remaining half holds more than
    # half of the weight), not half the kernel as when the end value is
    # extended (mode "nearest")
    assert out[0, 0] < 2.0 * _smooth(inner, width)[30, 0] + 1e-12
    assert np.allclose(out[:, 0], out[:, 1]) and out[25:, 0].max() == 0.0


def test_state_balance_equals_a_fresh_analysis(walk30):
    # the touch-up updates its ZMP analysis for the moved links only
    h = touch_up(bend(walk30[:60], 2.0), iterations=1)
    for st in h.states:
        full = balance(st.motion, st.body, contacts=st.contacts)
        for name in ("zmp", "distance", "projection", "com", "support", "positions", "accelerations"):
            assert np.allclose(getattr(st.balance, name), getattr(full, name), atol=1e-9, equal_nan=True), name


def _flight_gravity(motion, body, stages):
    com = center_of_mass(motion, body)
    return np.array([-2.0 * np.polyfit(np.arange(b - a) / motion.fps, com[a:b, 1], 2)[0] for a, b in stages])


def test_flight_gets_a_parabola_and_steady_angular_momentum(cmu):
    jump = cmu("16_05").resample(30)
    c = foot_contacts(jump)
    stages = flight_stages(c)
    assert len(stages) == 1
    bent = bend(jump, 1.0)
    body = Body.from_skeleton(jump)
    h = touch_up(bent, contacts=c, iterations=2)
    g = _flight_gravity(h.final, body, stages)
    assert np.all(np.abs(g - 9.81) < 0.02 * 9.81)
    a, b = stages[0]
    spread = [np.linalg.norm(hm[a:b] - hm[a:b].mean(axis=0), axis=1).mean() for hm in
              (angular_momentum(bent, body), angular_momentum(h.final, body))]
    assert spread[1] < 0.6 * spread[0]
    # the bent horizontal flight path is straightened (ballistic)
    com = center_of_mass(h.final, body)[a:b][:, [0, 2]]
    fit = np.column_stack([np.arange(b - a), np.ones(b - a)])
    resid = com - fit @ np.linalg.lstsq(fit, com, rcond=None)[0]
    assert np.abs(resid).max() < 0.01


def test_walks_have_no_flight_adjustment(walk30):
    c = foot_contacts(walk30)
    assert flight_stages(c) == []
    st = start(walk30, contacts=c, schedule=FLIGHT_SCHEDULE)
    assert step(st).motion is walk30
