"""Motion graphs (Kim et al. 2009, section 5.1): frame distance, local-minimum transitions, chunking."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import minimum_filter

from mocaplab import quat
from mocaplab.editing.graph import (
    MotionGraph,
    SimilarityWeights,
    build_graph,
    frame_distances,
    frame_features,
    joint_weights,
)
from mocaplab.motion import Motion, Skeleton

FPS = 30.0


def swing(n_frames: int, period: int, *, speed: float = 1.0, name: str = "swing") -> Motion:
    """A 4-joint chain walking forward (+z) with joints swinging sinusoidally: frames ``period`` apart are equal."""
    sk = Skeleton(
        ["hips", "thigh", "shin", "spine"],
        [-1, 0, 1, 0],
        [[0, 0, 0], [0.1, -0.1, 0], [0, -0.45, 0], [0, 0.3, 0]],
        end_site_parents=[2, 3],
        end_site_offsets=[[0, -0.45, 0], [0, 0.3, 0]],
    )
    t = np.arange(n_frames)
    phase = 2 * np.pi * t / period
    rot = np.zeros((n_frames, 4, 4))
    rot[..., 3] = 1.0
    rot[:, 1] = quat.from_axis_angle([1.0, 0, 0], 0.6 * np.sin(phase))
    rot[:, 2] = quat.from_axis_angle([1.0, 0, 0], 0.4 + 0.4 * np.cos(phase))
    rot[:, 3] = quat.from_axis_angle([0, 0, 1.0], 0.1 * np.sin(phase))
    root = np.stack([np.zeros(n_frames), 0.9 + 0.02 * np.cos(2 * phase), speed * t / FPS], axis=1)
    return Motion(sk, rot, root, FPS, name=name)


@pytest.fixture(scope="module")
def walk(mocap_dir):
    from mocaplab import data

    return data.cmu("16_15").resample(FPS)


def test_joint_weights_follow_subtree_length(walk):
    w = joint_weights(walk.skeleton)
    names = walk.skeleton.names
    assert w[0] == 1.0 and np.all((w > 0) & (w <= 1.0))
    assert w[1:].max() == pytest.approx(1.0)
    # a spine joint moves more of the body than a forearm, which moves more than a finger
    assert w[names.index("LowerBack")] > w[names.index("LeftForeArm")] > w[names.index("LeftHandIndex1")]
    assert w[names.index("LeftUpLeg")] > w[names.index("LeftFoot")]


def test_distance_is_a_squared_metric_blind_to_ground_placement(walk):
    D = frame_distances(walk[:40])
    assert np.allclose(np.diag(D), 0.0, atol=1e-6)
    assert np.allclose(D, D.T, atol=1e-6)
    assert np.all(D >= 0)
    # heading and ground position do not matter (root orientation is pitch/roll only,
    # velocities are in the body frame)
    moved = walk[:40].transformed(yaw=1.3, translation=(3.0, 0.0, -2.0))
    cross = frame_distances(walk[:40], moved)
    assert np.allclose(np.diag(cross), 0.0, atol=1e-4)
    # but the root height does
    up = walk[:40].replace(root_positions=walk[:40].root_positions + [0, 0.1, 0])
    assert np.allclose(np.diag(frame_distances(walk[:40], up)), SimilarityWeights().root_height * 0.01, rtol=1e-3)


def test_features_weights_scale_terms(walk):
    m = walk[:20]
    base = frame_features(m)
    only_angles = frame_features(
        m, SimilarityWeights(root_height=0, root_tilt=0, joint_velocities=0, root_velocity=0, root_angular_velocity=0)
    )
    assert base.shape[0] == only_angles.shape[0] == 20 and base.dtype == np.float32
    # zero weights switch terms off: fewer non-zero columns, smaller distances
    assert np.count_nonzero(np.any(only_angles != 0, axis=0)) < np.count_nonzero(np.any(base != 0, axis=0))
    assert np.all(frame_distances(only_angles) <= frame_distances(base) + 1e-5)
    with pytest.raises(ValueError, match="root_height"):
        SimilarityWeights(root_height=-1.0)
    with pytest.raises(TypeError, match="Motion"):
        frame_features(np.zeros((3, 4)))


def test_periodic_motion_has_transitions_at_the_period():
    period = 24
    m = swing(150, period)
    g = build_graph([m], threshold=1e-3, window=0.3, min_gap=0.3)
    assert len(g.pairs)
    lag = g.pairs[:, 1] - g.pairs[:, 0]
    assert np.all(lag % period == 0), lag
    assert np.all(g.costs < 1e-3)
    # every pair is a local minimum of D within the window, and distinct pairs are at least min_gap apart in a clip
    D = frame_distances(m)
    gap = int(np.ceil(0.3 * FPS))
    i, j = np.indices(D.shape)
    D[np.abs(i - j) < gap] = np.inf
    M = minimum_filter(D, size=2 * int(round(0.3 * FPS)) + 1, mode="nearest")
    for a, b in g.pairs:
        assert D[a, b] <= M[a, b] + 1e-6  # float32 features in the graph
        assert b - a >= gap


def test_chunking_gives_the_same_graph(walk):
    full = build_graph([walk], chunk=10_000)
    small = build_graph([walk], chunk=7)
    assert np.array_equal(full.pairs, small.pairs)
    assert np.allclose(full.costs, small.costs, rtol=1e-5, atol=1e-7)


def test_real_walk_links_gait_cycles(walk):
    g = build_graph([walk])
    assert 2 <= len(g.pairs) <= 30  # sparse: local minima only
    lag_s = (g.pairs[:, 1] - g.pairs[:, 0]) / FPS
    # a gait cycle of 16_15 lasts about 1.15 s: lags are whole cycles, never half a cycle (the other foot)
    cycles = lag_s / 1.15
    assert np.all(np.abs(cycles - np.round(cycles)) < 0.15)
    assert np.all(np.round(cycles) >= 1)
    assert np.all(g.costs < g.threshold)


def test_idle_stretch_gets_a_transition(mocap_dir):
    from mocaplab import data

    m = data.cmu("127_17").resample(FPS)  # run, stop, run
    g = build_graph([m])
    speed = np.linalg.norm(np.gradient(m.root_positions[:, [0, 2]], axis=0), axis=1) * FPS
    slow = [(a, b) for a, b in g.pairs if speed[a] < 0.3 and speed[b] < 0.3]
    assert slow, "the standing part should be similar to itself 0.3 s later"


def test_transitions_and_sparse_matrices():
    m = swing(100, 20)
    g = build_graph([m], threshold=1e-3)
    src, dst, cost = g.transitions()
    pairs = {tuple(p) for p in g.pairs.tolist()}
    for s, d in zip(src, dst, strict=True):
        assert (s, d - 1) in pairs or (d - 1, s) in pairs  # i -> j + 1 and j -> i + 1
        assert d < g.n_frames
    assert len(src) == 2 * len(g.pairs) - np.sum(g.pairs[:, 1] == g.n_frames - 1)
    T = g.transition_matrix()
    assert T.shape == (100, 100) and T.nnz == len(src)
    S = g.similar()
    assert (S != S.T).nnz == 0


def test_several_clips_share_one_graph():
    a = swing(90, 20, name="a")
    b = swing(60, 20, speed=1.0, name="b").transformed(yaw=0.5, translation=(2, 0, 2))
    g = build_graph([a, b], threshold=1e-3)
    assert g.n_frames == 150 and list(g.offsets) == [0, 90, 150]
    assert g.locate(95) == (1, 5)
    assert np.array_equal(g.clip_of[[0, 89, 90, 149]], [0, 0, 1, 1])
    cross = (g.pairs[:, 0] < 90) & (g.pairs[:, 1] >= 90)
    assert cross.any(), "same motion in both clips: transitions between them"
    # frames of different clips may be close in index: no min_gap between clips
    assert g.clip_index(b) == 1 and g.clip_index(a) == 0
    assert g.clip_index(swing(90, 21)) is None
    with pytest.raises(IndexError):
        g.locate(150)
    assert "2 clip(s)" in repr(g)


def test_input_errors(walk):
    with pytest.raises(ValueError, match="at least one motion"):
        build_graph([])
    with pytest.raises(ValueError, match="fps"):
        build_graph([walk, walk.resample(60)])
    with pytest.raises(ValueError, match="skeleton"):
        build_graph([walk, swing(50, 10)])
    with pytest.raises(ValueError, match="threshold"):
        build_graph([walk], threshold=0)
    with pytest.raises(ValueError, match="chunk"):
        build_graph([walk], chunk=0)
    with pytest.raises(TypeError, match=r"motions\[1\]"):
        build_graph([walk, "walk"])
    assert isinstance(build_graph(walk), MotionGraph)  # a single Motion is accepted


@pytest.mark.parametrize("clip", ["16_15", "09_06"])
def test_the_distance_of_two_moments_does_not_depend_on_the_frame_rate(mocap_dir, clip):
    # velocities differenced over VELOCITY_SPAN seconds, not one frame each side: over one frame the capture's
    # noise grew with the rate and the same two moments of 16_15 were 0.069 apart at 120 fps, 0.032 at 24 fps
    # (median relative difference over all pairs of moments 8-15 %, 95th percentile 56-62 %; now 2-4 % and 14-39 %)
    from mocaplab import data

    m = data.cmu(clip)
    t = np.arange(0.0, m.duration - 0.1, 1 / 24)

    def distances(fps):
        motion = m if fps == m.fps else m.resample(fps)
        f = frame_features(motion).astype(float)[np.round(t * fps).astype(int)]
        return ((f[:, None] - f[None]) ** 2).sum(-1)

    full = distances(120.0)
    for fps in (60.0, 30.0, 24.0):
        rel = np.abs(distances(fps) - full) / (full + 0.02)
        assert np.median(rel) < 0.05 and np.percentile(rel, 95) < 0.45, (fps, np.median(rel), np.percentile(rel, 95))
