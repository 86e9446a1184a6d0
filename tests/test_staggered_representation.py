"""Staggered pose representation (Coleman 2008, section 3): kernels, evaluation, validation."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from mocaplab import quat
from mocaplab.motion import Motion, Skeleton
from mocaplab.staggered import (
    bezier,
    compose_rotation,
    factor_rotation,
    fit_representation,
    quat_bezier,
    variable_names,
)
from mocaplab.staggered.representation import casteljau, locate, next_active


def chain_motion(n_frames: int = 121, fps: float = 60.0) -> Motion:
    """A 3-joint chain swinging with phase-shifted sines (analytic fixture)."""
    sk = Skeleton(["root", "upper", "lower"], [-1, 0, 1], [[0, 0, 0], [0, -0.4, 0], [0, -0.4, 0]])
    t = np.arange(n_frames) / fps
    rot = np.empty((n_frames, 3, 4))
    rot[:, 0] = quat.from_axis_angle([0, 1, 0], 0.3 * np.sin(2 * np.pi * 0.5 * t))
    rot[:, 1] = quat.from_axis_angle([1, 0, 0], 0.8 * np.sin(2 * np.pi * 0.7 * t))
    rot[:, 2] = quat.from_axis_angle([1, 0, 0], 0.5 * np.sin(2 * np.pi * 0.7 * t - 0.6))
    root = np.stack([0.6 * t, 0.9 + 0.02 * np.sin(2 * np.pi * 1.4 * t), np.zeros_like(t)], axis=1)
    return Motion(sk, rot, root, fps, name="chain")


def test_compose_and_factor_are_inverse(rng: np.random.Generator) -> None:
    a = quat.normalize(rng.normal(size=(20, 4)))
    c = quat.normalize(rng.normal(size=(20, 4)))
    b = factor_rotation(c, a)
    assert np.allclose(quat.angle(quat.mul(quat.inv(compose_rotation(a, b)), c)), 0.0, atol=1e-12)
    # the order matters: a (+) b applies b in a's frame, i.e. mul(a, b)
    assert np.allclose(compose_rotation(a, b), quat.mul(a, b))


def test_bezier_interpolates_ends_and_reproduces_lines() -> None:
    p0, p3 = np.array([0.0, 1.0, 2.0]), np.array([3.0, -1.0, 5.0])
    t = np.linspace(0, 1, 11)
    line = bezier(p0, p0 + (p3 - p0) / 3, p0 + 2 * (p3 - p0) / 3, p3, t)
    assert np.allclose(line, p0 + t[:, None] * (p3 - p0))


def test_quat_bezier_with_arc_controls_is_slerp() -> None:
    q1 = quat.from_axis_angle([0, 0, 1], 0.1)
    q4 = quat.from_axis_angle([0.3, 1, 0], 1.2)
    t = np.linspace(0, 1, 17)
    q2 = quat.slerp(q1, q4, 1 / 3)
    q3 = quat.slerp(q1, q4, 2 / 3)
    s = quat_bezier(q1, q2, q3, q4, t)
    assert np.allclose(np.abs(np.sum(s * quat.slerp(q1, q4, t), axis=-1)), 1.0, atol=1e-12)
    assert np.allclose(s[0], q1) and np.allclose(s[-1], q4)
    assert np.allclose(np.linalg.norm(s, axis=-1), 1.0)


def test_fast_kernel_matches_recursive_slerp(rng: np.random.Generator) -> None:
    base = quat.normalize(rng.normal(size=(30, 1, 4)))
    ctrl = quat.mul(base, quat.exp(rng.normal(scale=0.4, size=(30, 4, 3))))
    ctrl = np.where(np.sum(ctrl * ctrl[:, :1], axis=-1, keepdims=True) < 0, -ctrl, ctrl)
    t = rng.random(30)
    theta = np.arccos(np.clip(np.sum(ctrl[:, :3] * ctrl[:, 1:], axis=-1), -1, 1))
    a = casteljau(ctrl, theta, t)
    b = quat_bezier(ctrl[:, 0], ctrl[:, 1], ctrl[:, 2], ctrl[:, 3], t)
    assert np.allclose(a, b, atol=1e-12)


def test_locate_normalised_time_uses_each_variables_refined_knots() -> None:
    times = np.array([0.0, 1.0, 2.0])
    r = np.array([[0.0, 0.0], [0.2, -0.1], [0.0, 0.0]])
    act = np.ones((3, 2), dtype=bool)
    k0, k1, tn = locate(times, r, act, np.array([0.6, 1.2, 1.0]))
    # variable 0: knots 0, 1.2, 2 ; variable 1: knots 0, 0.9, 2
    assert k0[:, 0].tolist() == [0, 1, 0] and k1[:, 0].tolist() == [1, 2, 1]
    assert np.allclose(tn[:, 0], [0.6 / 1.2, 0.0, 1.0 / 1.2])
    assert k0[:, 1].tolist() == [0, 1, 1]
    assert np.allclose(tn[:, 1], [0.6 / 0.9, 0.3 / 1.1, 0.1 / 1.1])
    # non-staggered: refinements treated as zero
    _, _, tn0 = locate(times, r, act, np.array([0.6]), staggered=False)
    assert np.allclose(tn0, 0.6)


def test_next_active_skips_partial_poses() -> None:
    act = np.array([[1, 1], [0, 1], [1, 0], [1, 1]], dtype=bool)
    assert next_active(act).tolist() == [[2, 1], [2, 3], [3, 3], [-1, -1]]


def test_evaluation_hits_knots_and_reconstructs_exactly() -> None:
    m = chain_motion()
    times = np.array([0.0, 0.5, 1.1, 2.0])
    r = np.zeros((4, 4))
    r[1, 2] = 5 / 60
    r[2, 3] = -4 / 60
    sm = fit_representation(m, times, r, filter_sigma=None)  # knots on the clip's own values
    out = sm.evaluate()
    assert out.n_frames == m.n_frames
    assert quat.angle(quat.mul(quat.inv(out.rotations), m.rotations)).max() < 1e-9
    assert np.abs(out.root_positions - m.root_positions).max() < 1e-12
    # the extreme value of 'upper' at pose 1 is the clip at t_1 + r
    f = int(round((0.5 + 5 / 60) * 60))
    assert quat.angle(quat.mul(quat.inv(sm.rotation_values[1, 1]), m.rotations[f, 1])) < 1e-12
    assert variable_names(m.skeleton) == ("root_position", "root", "upper", "lower")
    assert sm.n_variables == 4 and sm.variables[2] == "upper"
    assert sm.editing_knots.sum() == 2


def test_non_staggered_pose_and_true_pose_differ_where_refined() -> None:
    m = chain_motion()
    r = np.zeros((3, 4))
    r[1, 2] = 0.1
    sm = fit_representation(m, np.array([0.0, 1.0, 2.0]), r, filter_sigma=None)
    root, rot = sm.true_pose(1)
    ns_root, ns_rot = sm.non_staggered_pose(1)
    f = 60
    assert quat.angle(quat.mul(quat.inv(rot), m.rotations[f])).max() < 1e-9
    assert np.allclose(ns_rot[[0, 2]], rot[[0, 2]], atol=1e-9)
    assert quat.angle(quat.mul(quat.inv(ns_rot[1]), m.rotations[66, 1])) < 1e-9
    assert sm.pose_motion(1, which="non-staggered").n_frames == 1
    with pytest.raises(ValueError, match="which"):
        sm.pose_motion(1, which="both")  # type: ignore[arg-type]


def test_zero_refinements_equal_non_staggered_evaluation() -> None:
    m = chain_motion()
    r = np.zeros((3, 4))
    r[1, 1:] = [0.05, 0.1, -0.08]
    sm = fit_representation(m, np.array([0.0, 1.0, 2.0]), r)
    a = sm.evaluate(staggered=False)
    b = sm.zero_refinements().evaluate()
    assert np.allclose(a.rotations, b.rotations) and np.allclose(a.root_positions, b.root_positions)
    assert quat.angle(quat.mul(quat.inv(a.rotations), m.rotations)).max() > 0.01


def test_validation_names_the_problem() -> None:
    m = chain_motion()
    sm = fit_representation(m, np.array([0.0, 1.0, 2.0]), np.zeros((3, 4)))
    r = np.zeros((3, 4))
    r[1, 2] = 1.5  # knot of 'upper' after the last pose
    with pytest.raises(ValueError, match="'upper' are out of order"):
        dataclasses.replace(sm, refinements=r)
    with pytest.raises(ValueError, match="refinements"):
        dataclasses.replace(sm, refinements=np.zeros((3, 3)))
    with pytest.raises(ValueError, match="strictly increasing"):
        dataclasses.replace(sm, times=np.array([0.0, 1.5, 1.0]))
    act = np.ones((3, 4), dtype=bool)
    act[0, 1] = False
    with pytest.raises(ValueError, match="first and last"):
        dataclasses.replace(sm, active=act)
    with pytest.raises(IndexError, match="pose index"):
        sm.true_pose(7)
    with pytest.raises(KeyError, match="No control variable"):
        sm.variable_index("tail")


def test_evaluate_is_cached_and_read_only() -> None:
    sm = fit_representation(chain_motion(), np.array([0.0, 1.0, 2.0]), np.zeros((3, 4)))
    a = sm.evaluate()
    assert sm.evaluate() is a
    assert not sm.refinements.flags.writeable and not sm.times.flags.writeable
