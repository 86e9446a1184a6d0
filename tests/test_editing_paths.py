"""Motion paths (Kim et al. 2009, section 3.1): tangents, normals, directions, Laplacian coordinates."""

from __future__ import annotations

import numpy as np
import pytest

from mocaplab.editing import MotionPath, stationary_segments
from mocaplab.editing.paths import central_tangents, ground_angle, laplacian_coordinates, rot90, wrap_angle


def test_straight_line_tangent_frame():
    p = np.c_[np.zeros(6), np.arange(6.0) * 0.1]  # walking along +z
    heads = np.full(6, 0.3)
    path = MotionPath(p, heads, 10.0)
    np.testing.assert_allclose(path.tangents, np.tile([0.0, 0.2], (6, 1)), atol=1e-12)
    # the normal is on the walker's left: +x when walking along +z (Y up, right-handed)
    np.testing.assert_allclose(path.normals, np.tile([0.2, 0.0], (6, 1)), atol=1e-12)
    np.testing.assert_allclose(path.directions, 0.3)
    assert path.length == pytest.approx(0.5)


def test_rot90_is_plus_90_degrees_of_yaw():
    v = np.array([[0.3, 1.0], [-2.0, 0.5]])
    np.testing.assert_allclose(wrap_angle(ground_angle(rot90(v)) - ground_angle(v)), np.pi / 2)


def test_laplacian_coordinates_reconstruct_points(rng):
    p = np.cumsum(rng.normal(size=(40, 2)), axis=0)
    xy = laplacian_coordinates(p)
    assert np.isnan(xy[0]).all() and np.isnan(xy[-1]).all()
    t = p[2:] - p[:-2]
    rec = p[:-2] + xy[1:-1, :1] * t + xy[1:-1, 1:] * rot90(t)
    np.testing.assert_allclose(rec, p[1:-1], atol=1e-12)


def test_laplacian_coordinates_are_similarity_invariant(rng):
    p = np.cumsum(rng.normal(size=(30, 2)), axis=0)
    a = 0.7
    rot = np.array([[np.cos(a), np.sin(a)], [-np.sin(a), np.cos(a)]])
    q = 2.5 * p @ rot.T + [3.0, -1.0]
    np.testing.assert_allclose(laplacian_coordinates(q), laplacian_coordinates(p), atol=1e-10)


def test_degenerate_tangents_are_interpolated():
    z = np.concatenate([np.arange(10) * 0.05, np.full(10, 0.45), 0.45 + np.arange(1, 11) * 0.05])
    x = np.concatenate([np.zeros(10), np.zeros(10), np.arange(1, 11) * 0.05])
    path = MotionPath(np.c_[x, z], np.zeros(30), 30.0)
    assert path.degenerate[11:19].all() and not path.degenerate[:9].any()
    # every filled tangent is a convex combination of its neighbours: never zero, direction in between
    assert np.all(np.linalg.norm(path.tangents, axis=1) > 0.04)
    ang = ground_angle(path.tangents[11:19])
    assert np.all(np.diff(ang) >= -1e-12)  # turns monotonically from +z towards +x
    assert ang[0] >= 0 and ang[-1] <= np.pi / 4 + 1e-9


def test_tangent_operator_matches_tangents(rng):
    p = np.cumsum(rng.normal(scale=0.05, size=(50, 2)), axis=0)
    p[20:26] = p[20]  # a stationary stretch
    path = MotionPath(p, np.zeros(50), 30.0)
    assert path.degenerate[21:25].all()
    np.testing.assert_allclose(path.tangent_operator() @ p, path.tangents, atol=1e-12)
    np.testing.assert_allclose(central_tangents(p)[~path.degenerate], path.tangents[~path.degenerate])


def test_from_motion_directions_give_back_headings(cmu):
    m = cmu("16_11").resample(30)
    path = MotionPath.from_motion(m)
    assert path.positions.shape == (m.n_frames, 2)
    np.testing.assert_allclose(path.positions, m.root_positions[:, [0, 2]])
    np.testing.assert_allclose(wrap_angle(path.directions + path.tangent_angles - path.headings), 0.0, atol=1e-9)
    # a walker faces roughly along its path: the relative direction is steady
    spread = np.abs(wrap_angle(path.directions - np.median(path.directions)))
    assert np.median(spread) < 0.35


def test_with_positions_keeps_relative_directions(cmu):
    m = cmu("16_15").resample(30)
    path = MotionPath.from_motion(m)
    a = 0.9
    rot = np.array([[np.cos(a), np.sin(a)], [-np.sin(a), np.cos(a)]])
    moved = path.with_positions(path.positions @ rot.T + [1.0, 2.0])
    np.testing.assert_allclose(wrap_angle(moved.directions - path.directions), 0.0, atol=1e-9)
    np.testing.assert_allclose(wrap_angle(moved.headings - path.headings - a), 0.0, atol=1e-9)


def test_local_offset_round_trip(cmu):
    path = MotionPath.from_motion(cmu("02_01").resample(30))
    q = path.from_local(40, (0.5, -1.25))
    assert path.local_offset(40, q) == pytest.approx((0.5, -1.25))
    f, l = path.local_direction(40, path.tangents[40])
    assert (f, l) == pytest.approx((1.0, 0.0))


def test_stationary_segments_walk_stop(cmu):
    stop = cmu("16_34").resample(30)
    segs = stationary_segments(stop, contacts=None)
    assert len(segs) == 1 and segs[0][1] == stop.n_frames
    assert stop.n_frames - segs[0][0] >= 9  # at least 0.3 s standing at the end
    feet = stationary_segments(stop, contacts="auto")
    assert feet[0][0] <= segs[0][0]  # planted feet start earlier than the speed test
    assert stationary_segments(cmu("16_15").resample(30), contacts="auto") == []


def test_bad_input():
    with pytest.raises(ValueError, match=r"shape \(F, 2\)"):
        MotionPath(np.zeros((2, 2)), np.zeros(2), 30.0)
    with pytest.raises(ValueError, match="headings"):
        MotionPath(np.zeros((5, 2)), np.zeros(4), 30.0)
    with pytest.raises(TypeError, match="Motion"):
        MotionPath.from_motion(np.zeros((5, 3)))  # type: ignore[arg-type]
    still = MotionPath(np.zeros((5, 2)), np.zeros(5), 30.0)
    assert not still.has_tangents
    with pytest.raises(ValueError, match="stationary"):
        still.tangent_operator()
