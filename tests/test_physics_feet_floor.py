"""Touch-up on any feet and any floor (issue 24, items 3 and 4).

* Feet without toe joints: the same captured walk with its toe joints
  dropped (the toe joint's position becoming the ankle's end site, or no end
  site at all) is labelled through toe-off and balanced on a support polygon
  with a toe, within 1.3x of the walk with toes (mean ZMP distance, input
  and after touch-up).
* The floor the feet stand on: a walk lifted 0.5 m has the same ZMP
  distances and the same touch-up (up to the lift); a walk up a 10-degree
  slope keeps its contact labels.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from mocaplab import quat
from mocaplab.contacts import foot_contacts, intervals_from_mask
from mocaplab.motion import Motion, Skeleton
from mocaplab.physics import balance, touch_up


def drop_toes(motion: Motion, *, end_sites: bool = True) -> Motion:
    """The same poses on a skeleton without toe joints (their descendants dropped too).

    With ``end_sites`` the toe joint's position becomes its ankle's end site.
    """
    sk = motion.skeleton
    gone: set[int] = set()
    for j, name in enumerate(sk.names):
        if "toe" in name.lower() or int(sk.parents[j]) in gone:
            gone.add(j)
    keep = [j for j in range(sk.n_joints) if j not in gone]
    new_index = {old: new for new, old in enumerate(keep)}
    parents = [-1] + [new_index[int(sk.parents[j])] for j in keep[1:]]
    esp = [new_index[int(p)] for p in sk.end_site_parents if int(p) in new_index]
    eso = [o for p, o in zip(sk.end_site_parents, sk.end_site_offsets, strict=True) if int(p) in new_index]
    if end_sites:
        for j in sorted(gone):
            if int(sk.parents[j]) in new_index:
                esp.append(new_index[int(sk.parents[j])])
                eso.append(sk.offsets[j])
    skeleton = Skeleton(
        [sk.names[j] for j in keep], parents, sk.offsets[keep], channels=tuple(sk.channels[j] for j in keep),
        end_site_parents=np.array(esp, dtype=np.int64), end_site_offsets=np.array(eso).reshape(-1, 3),
    )
    return Motion(skeleton, motion.rotations[:, keep], motion.root_positions, motion.fps)


def _touched(motion: Motion, **options) -> float:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        h = touch_up(motion, **options)
    return float(h.errors[h.best])


@pytest.fixture(scope="module")
def walk(cmu):
    return cmu("16_15")


@pytest.mark.parametrize("end_sites", [True, False], ids=["end-site", "no-end-site"])
@pytest.mark.parametrize("fps", [120, 30])
def test_a_toeless_walk_balances_like_the_walk_with_toes(walk, end_sites, fps):
    toes = walk if fps == 120 else walk.resample(fps)
    toeless = drop_toes(toes, end_sites=end_sites)
    assert "LeftToeBase" not in toeless.skeleton.names
    c = foot_contacts(toeless)
    assert c.planted_any().all(), "a walk has no flight"
    with_toes, without = balance(toes).mean_distance, balance(toeless).mean_distance
    assert without <= 1.3 * with_toes, (1000 * without, 1000 * with_toes)
    assert _touched(toeless) <= 1.3 * _touched(toes)


def test_toe_off_is_labelled_on_a_toeless_foot(walk):
    """The ankle of a toe-less foot stays planted while the toe joint of the walk with toes does (toe-off)."""
    toeless = drop_toes(walk)
    with_toes = foot_contacts(walk)
    without = foot_contacts(toeless)
    for side in ("Left", "Right"):
        foot = with_toes.of(f"{side}Foot") | with_toes.of(f"{side}ToeBase")
        covered = np.mean(without.of(f"{side}Foot")[foot])
        assert covered > 0.95, (side, covered)
        # the toe-only frames are the ones the ankle alone misses
        toe_only = with_toes.of(f"{side}ToeBase") & ~with_toes.of(f"{side}Foot")
        assert toe_only.sum() > 10 and without.of(f"{side}Foot")[toe_only].mean() > 0.9


def test_a_toeless_support_polygon_leaves_out_the_lifted_heel(walk):
    toeless = drop_toes(walk)
    b = balance(toeless)
    with_toes = foot_contacts(walk)
    toe_only = with_toes.of("LeftToeBase") & ~with_toes.of("LeftFoot")
    # the left foot's points: two heel points, two ball points and the tip
    left = np.flatnonzero(np.isclose(b.support[0, :, 0], b.support[0, :, 0]))[:5]
    heel_active = b.active[toe_only][:, left[:2]].mean()
    toe_active = b.active[toe_only][:, left[2:]].mean()
    assert toe_active > 0.9 and heel_active < 0.5, (toe_active, heel_active)


def _foot_events(motion: Motion) -> dict[str, np.ndarray]:
    """Heel strikes and toe-offs of each foot (ankle or toe planted), in seconds: (n, 2) per side.

    A label is the state at a frame's instant, so a contact labelled on
    frames ``a .. b - 1`` started between frames ``a - 1`` and ``a`` and
    ended between ``b - 1`` and ``b``: its events are timed midway.  Only
    contacts that start and end inside the clip.
    """
    c = foot_contacts(motion)
    out = {}
    for side in ("Left", "Right"):
        planted = np.any([c.of(j) for j in c.joints if j.startswith(side)], axis=0)
        events = [(a, b) for a, b in intervals_from_mask(planted) if a > 0 and b < motion.n_frames]
        out[side] = (np.array(events, dtype=float).reshape(-1, 2) - 0.5) / motion.fps
    return out


@pytest.mark.parametrize("clip", ["16_15", "02_01"])
def test_contacts_are_timed_alike_at_any_frame_rate(cmu, clip):
    """Heel strikes and toe-offs at 60 and 30 fps within half a 30 fps frame of those at 120 fps.

    Each rate times an event to within half its own frame, so the bound is
    half a frame at 30 fps plus half a frame at 120 fps (20.8 ms).  With
    speeds by central differences and rules in whole frames, 02_01 was 29 ms
    late at 30 fps, and both walks lost 1.3-1.5 % of their planted frames
    at 24 fps (now at most 0.7 %).
    """
    walk = cmu(clip)
    reference = _foot_events(walk)
    share = foot_contacts(walk).mask.mean()
    for fps in (60, 30):
        found = _foot_events(walk.resample(fps))
        for side, events in reference.items():
            assert found[side].shape == events.shape, (fps, side, found[side], events)
            late = 1000 * (found[side] - events)
            assert np.abs(late).max() <= 1000 * (1 / 60 + 1 / 240) + 1e-6, (fps, side, late.round(1))
    for fps in (60, 30, 24):
        assert abs(foot_contacts(walk.resample(fps)).mask.mean() - share) < 0.01, (fps, share)


@pytest.mark.parametrize(
    "clip",
    [
        "16_15",
        pytest.param("02_01", marks=pytest.mark.xfail(strict=True, reason=(
            "the whole-clip mean at 30 fps is 1.32x 120 fps's (4.10 vs 3.10 mm): the first and last 0.1 s, which no "
            "adjustment corrects, hold 52 and 44 mm at 30 fps against 28 and 29 at 120 (the ZMP's accelerations at "
            "the clip's ends depend on the rate); the interior is 0.82 vs 1.27 mm"))),
    ],
)
def test_a_walk_at_30_fps_is_balanced_and_touched_up_as_at_120(cmu, clip):
    """The mean ZMP distance of the input (24 and 30 fps) and of the touch-up (30 fps) as at 120 fps."""
    walk = cmu(clip)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fast, slow = touch_up(walk), touch_up(walk.resample(30))
    for fps in (30, 24):
        ratio = balance(walk.resample(fps)).mean_distance / balance(walk).mean_distance
        assert 1 / 1.1 <= ratio <= 1.1, (fps, ratio)
    interior = slow.mean_zmp_distance_interior[slow.best] / fast.mean_zmp_distance_interior[fast.best]
    assert interior <= 1.15, interior
    whole = slow.mean_zmp_distance[slow.best] / fast.mean_zmp_distance[fast.best]
    assert whole <= 1.15, whole


def test_a_lifted_walk_balances_and_touches_up_as_on_the_floor(walk):
    """Lifted 0.5 m and 1 m: the same numbers (ground estimated under both); against the floor, y = 0 there."""
    clip = walk.resample(30)
    half, one = (clip.with_root(root_positions=clip.root_positions + [0.0, h, 0.0]) for h in (0.5, 1.0))
    a, b = balance(half), balance(one)
    np.testing.assert_allclose(b.distance, a.distance, atol=1e-6, equal_nan=True)
    np.testing.assert_allclose(b.zmp - [0.0, 0.5, 0.0], a.zmp, atol=1e-6, equal_nan=True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ha, hb, h0 = touch_up(half), touch_up(one), touch_up(clip)
    np.testing.assert_allclose(hb.errors, ha.errors, atol=1e-6)
    pa = ha.states[ha.best].motion.global_positions()
    pb = hb.states[hb.best].motion.global_positions()
    np.testing.assert_allclose(pb - [0.0, 0.5, 0.0], pa, atol=1e-6)
    # on the floor the ground is y = 0 exactly, 1 cm below the estimate of the lifted walk's
    on_floor = balance(clip)
    assert np.allclose(on_floor.zmp[np.isfinite(on_floor.zmp[:, 1]), 1], 0.0)
    assert abs(a.mean_distance - on_floor.mean_distance) < 0.001
    assert ha.errors[ha.best] < 1.15 * h0.errors[h0.best]
    # the paper's y = 0 ground misjudges the lifted walk
    assert balance(half, floor="y=0").mean_distance > 1.5 * on_floor.mean_distance


def _uphill(motion: Motion, degrees: float) -> Motion:
    forward = (motion.root_positions[-1] - motion.root_positions[0]) * [1.0, 0.0, 1.0]
    forward /= np.linalg.norm(forward)
    q = quat.from_axis_angle(np.cross(forward, [0.0, 1.0, 0.0]), np.radians(degrees))
    s0 = motion.root_positions[0] * [1.0, 0.0, 1.0]
    return motion.with_root(root_positions=s0 + quat.rotate(q, motion.root_positions - s0),
                            root_rotations=quat.mul(q, motion.rotations[:, 0]))


def test_a_walk_up_a_slope_keeps_its_contacts_and_its_zmp_on_the_slope(walk):
    clip = walk.resample(30)
    slope = _uphill(clip, 10.0)
    a, b = foot_contacts(clip), foot_contacts(slope)
    agree = np.mean(a.mask == b.mask)
    assert agree > 0.97, agree
    # the ZMP lies on the estimated floor, 10 degrees up the walk, not on y = 0
    bal = balance(slope, contacts=b)
    ok = np.isfinite(bal.zmp[:, 0])
    xz, y = bal.zmp[ok][:, [0, 2]], bal.zmp[ok, 1]
    design = np.column_stack([xz, np.ones(len(y))])
    coef, residual = np.linalg.lstsq(design, y, rcond=None)[:2]
    assert np.degrees(np.arctan(np.linalg.norm(coef[:2]))) == pytest.approx(10.0, abs=0.5)
    assert np.sqrt(residual[0] / len(y)) < 1e-6
    flat = balance(slope, contacts=b, floor="y=0")
    assert np.allclose(flat.zmp[ok, 1], 0.0)


def test_toeless_shared_file_has_no_fake_flight(mocap_dir):
    import mocaplab as ml

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = ml.load(mocap_dir / "realworld" / "bvhtoolbox" / "test_mocapbank.bvh")
    c = foot_contacts(m)
    assert c.planted_any().all()
    assert balance(m, contacts=c).mean_distance < 0.03
