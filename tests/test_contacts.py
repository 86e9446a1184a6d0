"""Contact detection: synthetic feet with known answers, and real CMU gaits."""

from __future__ import annotations

from itertools import pairwise

import numpy as np
import pytest

from mocaplab.contacts import (
    Contacts,
    clean_mask,
    default_foot_joints,
    foot_contacts,
    intervals_from_mask,
    mask_from_intervals,
    stillness_contacts,
)
from mocaplab.motion import Motion, Skeleton

FPS = 120.0


def _moving_joints(tracks: dict[str, np.ndarray], fps: float = FPS) -> Motion:
    """A still root with one child joint per track, placed at the track's positions (F, 3)."""
    names = ["Hips", *tracks]
    frames = len(next(iter(tracks.values())))
    sk = Skeleton(names, [-1] + [0] * len(tracks), np.zeros((len(names), 3)))
    tr = np.zeros((frames, len(names), 3))
    for k, track in enumerate(tracks.values(), start=1):
        tr[:, k] = track
    rot = np.tile([0.0, 0.0, 0.0, 1.0], (frames, len(names), 1))
    return Motion(sk, rot, np.zeros((frames, 3)), fps, translations=tr)


def _step_track() -> np.ndarray:
    """Planted at x=0 for frames 0..99, a 0.2 m high step of 1 m over frames 100..159, planted at x=1."""
    i = np.arange(240)
    x = np.clip((i - 99) / 61.0, 0.0, 1.0)
    return np.stack([x, 0.2 * np.sin(np.pi * x), np.zeros_like(x)], axis=1)


# ------------------------------------------------------------ masks, intervals
def test_intervals_and_masks_round_trip(rng):
    for n in (0, 1, 7, 100):
        for _ in range(20):
            m = rng.random(n) < rng.random()
            iv = intervals_from_mask(m)
            assert np.array_equal(mask_from_intervals(iv, n), m)
            assert all(0 <= a < b <= n for a, b in iv)
            assert all(b1 < a2 for (_, b1), (a2, _) in pairwise(iv))  # disjoint and not touching


def test_intervals_known_answer():
    assert intervals_from_mask([True, True, False, True]) == [(0, 2), (3, 4)]
    assert intervals_from_mask(np.zeros(5, dtype=bool)) == []
    assert mask_from_intervals([(0, 2), (3, 4)], 5).tolist() == [True, True, False, True, False]


def test_mask_from_intervals_rejects_out_of_range():
    with pytest.raises(ValueError, match="start <= stop <= 4"):
        mask_from_intervals([(2, 6)], 4)
    with pytest.raises(ValueError, match="1-D"):
        intervals_from_mask(np.zeros((3, 2), dtype=bool))


def test_clean_mask_fills_gaps_then_drops_blips():
    m = np.array([1, 1, 1, 0, 1, 1, 0, 0, 0, 1, 0, 0, 1, 1, 1, 1], dtype=bool)
    out = clean_mask(m, min_length=3, max_gap=1)
    # the 1-frame gap at 3 is filled; the lone frame 9 is dropped; the 2-frame gap at 10-11 stays
    assert intervals_from_mask(out) == [(0, 6), (12, 16)]
    # a gap at the clip boundary is not "between" two contacts
    assert intervals_from_mask(clean_mask([0, 1, 1, 1], max_gap=2)) == [(1, 4)]
    both = clean_mask(np.stack([m, ~m], axis=1), min_length=3, max_gap=1)
    assert np.array_equal(both[:, 0], out)


# ------------------------------------------------------------------ Contacts
def test_contacts_object():
    mask = np.array([[1, 0], [1, 1], [0, 1], [0, 0]], dtype=bool)
    c = Contacts(["LeftFoot", "RightFoot"], mask, 120)
    mask[0, 0] = False  # the object holds its own copy
    assert c.joints == ("LeftFoot", "RightFoot") and c.n_frames == 4 and c.fps == 120.0
    assert c.of("LeftFoot").tolist() == [True, True, False, False]
    assert c.intervals("RightFoot") == [(1, 3)]
    assert c.planted_any().tolist() == [True, True, True, False]
    assert not c.mask.flags.writeable
    with pytest.raises(ValueError):
        c.mask[0, 0] = False
    with pytest.raises(KeyError, match="LeftFoot"):
        c.of("Head")
    assert np.allclose(c.times, np.arange(4) / 120)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"joints": ("a", "b"), "mask": np.zeros((3, 3), dtype=bool), "fps": 30}, r"shape \(F, 2\)"),
        ({"joints": ("a", "a"), "mask": np.zeros((3, 2), dtype=bool), "fps": 30}, "unique"),
        ({"joints": ("a",), "mask": np.zeros((3, 1), dtype=bool), "fps": 0}, "fps"),
        ({"joints": ("a",), "mask": np.full((3, 1), 0.5), "fps": 30}, "boolean"),
    ],
)
def test_contacts_validation(kwargs, message):
    with pytest.raises(ValueError, match=message):
        Contacts(**kwargs)


# ------------------------------------------------------ foot_contacts: synthetic
def test_foot_contacts_synthetic_step_known_answer():
    m = _moving_joints({"LeftFoot": _step_track()})
    c = foot_contacts(m, joints=["LeftFoot"])
    # the swing starts at frame 99 and ends at 160 with a kink: the spline's speed there is already about
    # half the swing's 2 m/s (as central differences were), so those frames are not planted
    assert c.intervals("LeftFoot") == [(0, 99), (161, 240)]
    assert c.mask.shape == (240, 1)


def test_foot_contacts_height_threshold_and_floor_reference():
    track = np.zeros((120, 3))
    track[:, 1] = 0.5  # a foot held perfectly still, 0.5 m above the ground
    m = _moving_joints({"LeftFoot": track, "RightFoot": np.zeros((120, 3))})
    absolute = foot_contacts(m, joints=["LeftFoot", "RightFoot"], floor="ground")
    assert not absolute.of("LeftFoot").any()
    assert absolute.of("RightFoot").all()
    # relative to the clip's own floor level, the still high foot is "on its floor"
    assert foot_contacts(m, joints=["LeftFoot"], floor="clip").of("LeftFoot").all()
    assert foot_contacts(m, joints=["LeftFoot"], floor="ground", height=0.6).of("LeftFoot").all()


def test_foot_contacts_removes_blips_and_fills_gaps(rng):
    track = np.zeros((240, 3))
    # swing: moving fast except 2 slow frames in the middle (a blip)
    track[60:180, 0] = np.linspace(0, 2.0, 120)
    track[119:121, 0] = track[119, 0]
    track[180:, 0] = 2.0
    # a one-frame jerk during the first stance (a gap)
    track[30, 0] = 0.02
    m = _moving_joints({"LeftFoot": track})
    raw = foot_contacts(m, joints=["LeftFoot"], min_duration=0, max_gap=0)
    assert len(raw.intervals("LeftFoot")) > 2
    c = foot_contacts(m, joints=["LeftFoot"])
    iv = c.intervals("LeftFoot")
    assert len(iv) == 2
    assert iv[0][0] == 0 and iv[1][1] == 240


def test_foot_contacts_rejects_bad_arguments():
    m = _moving_joints({"LeftFoot": _step_track()})
    with pytest.raises(ValueError, match="height"):
        foot_contacts(m, joints=["LeftFoot"], height=-1)
    with pytest.raises(ValueError, match="speed"):
        foot_contacts(m, joints=["LeftFoot"], speed=0)
    with pytest.raises(ValueError, match="floor"):
        foot_contacts(m, joints=["LeftFoot"], floor="sky")
    with pytest.raises(ValueError, match="min_duration"):
        foot_contacts(m, joints=["LeftFoot"], min_duration=-0.1)
    with pytest.raises(KeyError, match="Ankle"):
        foot_contacts(m, joints=["Ankle"])
    with pytest.raises(ValueError, match=r"with_roles\(right_ankle="):
        foot_contacts(m)  # no right foot in this skeleton
    with pytest.raises(TypeError, match="Motion"):
        foot_contacts(np.zeros((3, 3)))


# ---------------------------------------------------- stillness: synthetic
def _pause_track(still_frames: int, *, speed: float = 2.0, total: int = 240) -> np.ndarray:
    """Moving along x at ``speed`` m/s, pausing for ``still_frames`` frames from frame 60."""
    v = np.full(total, speed / FPS)
    v[60 : 60 + still_frames] = 0.0
    x = np.concatenate([[0.0], np.cumsum(v[1:])])
    return np.stack([x, np.zeros(total), np.zeros(total)], axis=1)


def test_stillness_needs_the_minimum_duration():
    short = _moving_joints({"LeftFoot": _pause_track(24)})  # 0.2 s
    long = _moving_joints({"LeftFoot": _pause_track(60)})  # 0.5 s
    assert stillness_contacts(short, joints=["LeftFoot"], tolerance=0.01).intervals("LeftFoot") == []
    assert stillness_contacts(long, joints=["LeftFoot"], tolerance=0.01).intervals("LeftFoot") == [(59, 120)]
    # a 0.2 s minimum accepts the short pause
    c = stillness_contacts(short, joints=["LeftFoot"], tolerance=0.01, min_duration=0.2)
    assert c.intervals("LeftFoot") == [(59, 84)]


def test_stillness_expands_over_frames_within_tolerance():
    # at 2 m/s a frame moves 1.67 cm: a 3 cm tolerance takes in one more frame on each side
    m = _moving_joints({"LeftFoot": _pause_track(60)})
    assert stillness_contacts(m, joints=["LeftFoot"], tolerance=0.03).intervals("LeftFoot") == [(58, 121)]


def test_stillness_tolerates_noise_below_tolerance(rng):
    track = _pause_track(90)
    track[59:150] += rng.normal(scale=0.002, size=(91, 3))
    m = _moving_joints({"LeftFoot": track})
    (a, b), *rest = stillness_contacts(m, joints=["LeftFoot"], tolerance=0.015).intervals("LeftFoot")
    assert not rest and abs(a - 59) <= 1 and abs(b - 150) <= 1


def test_stillness_max_height():
    track = np.zeros((120, 3))
    track[:, 1] = 0.4
    m = _moving_joints({"LeftHand": track})
    assert stillness_contacts(m, joints=["LeftHand"]).of("LeftHand").all()
    assert not stillness_contacts(m, joints=["LeftHand"], max_height=0.2).of("LeftHand").any()


def test_stillness_short_clip_and_bad_tolerance():
    m = _moving_joints({"LeftFoot": np.zeros((10, 3))})
    assert not stillness_contacts(m, joints=["LeftFoot"]).mask.any()
    with pytest.raises(ValueError, match="tolerance"):
        stillness_contacts(m, joints=["LeftFoot"], tolerance=0)


# --------------------------------------------------------------- real CMU data
def _feet(c: Contacts) -> tuple[np.ndarray, np.ndarray]:
    """(left planted, right planted): a foot is planted when its ankle or toe is."""
    left = np.any([c.of(j) for j in c.joints if j.startswith(("Left", "l"))], axis=0)
    right = np.any([c.of(j) for j in c.joints if j.startswith(("Right", "r"))], axis=0)
    return left, right


def test_default_foot_joints(cmu):
    assert default_foot_joints(cmu("16_15")) == ("LeftFoot", "LeftToeBase", "RightFoot", "RightToeBase")
    assert default_foot_joints(cmu("60_10").skeleton) == ("lFoot", "rFoot")


@pytest.mark.parametrize("detector", [foot_contacts, stillness_contacts])
@pytest.mark.parametrize("clip", ["16_15", "02_01"])
def test_walk_feet_alternate_with_plausible_stance(cmu, clip, detector):
    m = cmu(clip)
    c = detector(m)
    left, right = _feet(c)
    # single support alternates between the feet: L R L R ...
    single = np.where(left & ~right, 1, np.where(right & ~left, 2, 0))
    seq = [int(s) for s in single if s]
    runs = [seq[0]] + [b for a, b in pairwise(seq) if b != a]
    assert len(runs) >= 5
    assert all(a != b for a, b in pairwise(runs))
    # double support exists and no foot is in the air for long on a walk
    assert (left & right).sum() >= 0.05 * m.n_frames
    assert (~left & ~right).mean() < 0.03
    # stance share of each complete gait cycle (stance start to next stance start)
    shares = []
    for side in (left, right):
        iv = [(a, b) for a, b in intervals_from_mask(side) if a > 0 and b < m.n_frames]
        starts = [a for a, _ in intervals_from_mask(side)]
        for a, b in iv:
            later = [s for s in starts if s > a]
            if later:
                shares.append((b - a) / (later[0] - a))
    assert len(shares) >= 2
    assert all(0.5 <= s <= 0.75 for s in shares), shares


def test_run_has_flight_phases(cmu):
    m = cmu("09_06")
    left, right = _feet(foot_contacts(m))
    assert left.any() and right.any()
    assert not (left & right).any()  # no double support when running
    flight = intervals_from_mask(~left & ~right)
    interior = [(a, b) for a, b in flight if a > 0 and b < m.n_frames]
    assert len(interior) >= 1
    assert all(b - a >= 0.05 * m.fps for a, b in interior)  # airborne for at least 50 ms
    # Coleman's 0.25 s minimum is longer than a running stance: no stillness contact
    assert not stillness_contacts(m).mask.any()


def test_detectors_do_not_touch_the_motion(cmu):
    m = cmu("16_15")[:120]
    before = np.array(m.rotations), np.array(m.root_positions)
    foot_contacts(m)
    stillness_contacts(m)
    assert np.array_equal(before[0], m.rotations) and np.array_equal(before[1], m.root_positions)
