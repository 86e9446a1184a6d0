"""Quaternion identities, against scipy where it has the same operation."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mocaplab import quat


def random_quats(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    return Rotation.random(int(np.prod(shape)), random_state=rng).as_quat().reshape(shape + (4,))


def same_rotation(a: np.ndarray, b: np.ndarray, atol: float = 1e-12) -> bool:
    """q and -q are the same rotation."""
    d = np.minimum(np.abs(a - b).max(axis=-1), np.abs(a + b).max(axis=-1))
    return bool(np.all(d < atol))


def test_identity_shape_and_value():
    q = quat.identity((2, 3))
    assert q.shape == (2, 3, 4)
    assert np.array_equal(q[1, 2], [0.0, 0.0, 0.0, 1.0])


def test_mul_matches_scipy_composition(rng):
    a, b = random_quats(rng, (50,)), random_quats(rng, (50,))
    expected = (Rotation.from_quat(a) * Rotation.from_quat(b)).as_quat()
    assert same_rotation(quat.mul(a, b), expected)


def test_mul_applies_right_factor_first(rng):
    a, b = random_quats(rng, (20,)), random_quats(rng, (20,))
    v = rng.normal(size=(20, 3))
    assert np.allclose(quat.rotate(quat.mul(a, b), v), quat.rotate(a, quat.rotate(b, v)), atol=1e-12)


def test_mul_identity_and_inverse(rng):
    q = random_quats(rng, (30,))
    assert np.allclose(quat.mul(q, quat.identity((30,))), q, atol=1e-15)
    assert same_rotation(quat.mul(q, quat.inv(q)), quat.identity((30,)))
    assert same_rotation(quat.mul(quat.inv(q), q), quat.identity((30,)))


def test_mul_is_associative(rng):
    a, b, c = (random_quats(rng, (10,)) for _ in range(3))
    assert np.allclose(quat.mul(quat.mul(a, b), c), quat.mul(a, quat.mul(b, c)), atol=1e-14)


def test_mul_broadcasts(rng):
    a = random_quats(rng, (5, 1))
    b = random_quats(rng, (1, 7))
    out = quat.mul(a, b)
    assert out.shape == (5, 7, 4)
    assert np.allclose(out[3, 4], quat.mul(a[3, 0], b[0, 4]))


def test_rotate_matches_scipy(rng):
    q = random_quats(rng, (40,))
    v = rng.normal(size=(40, 3))
    assert np.allclose(quat.rotate(q, v), Rotation.from_quat(q).apply(v), atol=1e-12)


def test_rotate_preserves_length(rng):
    q = random_quats(rng, (40,))
    v = rng.normal(size=(40, 3))
    assert np.allclose(np.linalg.norm(quat.rotate(q, v), axis=-1), np.linalg.norm(v, axis=-1))


def test_matrix_round_trip(rng):
    q = random_quats(rng, (25,))
    m = quat.to_matrix(q)
    assert np.allclose(m, Rotation.from_quat(q).as_matrix(), atol=1e-12)
    assert same_rotation(quat.from_matrix(m), q)


def test_log_exp_round_trip(rng):
    q = random_quats(rng, (200,))
    assert same_rotation(quat.exp(quat.log(q)), q)
    r = rng.uniform(-1.0, 1.0, size=(200, 3)) * 3.0  # |r| < pi * sqrt(3)
    r = r[np.linalg.norm(r, axis=-1) < np.pi - 1e-6]
    assert np.allclose(quat.log(quat.exp(r)), r, atol=1e-12)


def test_log_matches_scipy_rotvec(rng):
    q = random_quats(rng, (50,))
    assert np.allclose(quat.log(q), Rotation.from_quat(q).as_rotvec(), atol=1e-12)


def test_log_exp_small_angles_are_exact():
    r = np.array([[1e-10, 0.0, 0.0], [0.0, 3e-9, -2e-9], [0.0, 0.0, 0.0]])
    q = quat.exp(r)
    assert np.allclose(np.linalg.norm(q, axis=-1), 1.0)
    assert np.allclose(quat.log(q), r, rtol=1e-12, atol=1e-24)


def test_log_is_sign_invariant(rng):
    q = random_quats(rng, (20,))
    assert np.allclose(quat.log(q), quat.log(-q), atol=1e-14)


def test_angle_of_axis_angle():
    q = quat.from_axis_angle([0.0, 0.0, 2.0], 0.75)
    assert quat.angle(q) == pytest.approx(0.75)
    assert np.allclose(q, [0.0, 0.0, np.sin(0.375), np.cos(0.375)])


def test_slerp_endpoints_and_midpoint(rng):
    a, b = random_quats(rng, (30,)), random_quats(rng, (30,))
    assert same_rotation(quat.slerp(a, b, 0.0), a)
    assert same_rotation(quat.slerp(a, b, 1.0), b)
    mid = quat.slerp(a, b, 0.5)
    # equal angular distance to both ends, half the full distance
    d_ab = quat.angle(quat.mul(b, quat.inv(a)))
    d_am = quat.angle(quat.mul(mid, quat.inv(a)))
    d_mb = quat.angle(quat.mul(b, quat.inv(mid)))
    assert np.allclose(d_am, d_ab / 2, atol=1e-10)
    assert np.allclose(d_mb, d_ab / 2, atol=1e-10)


def test_slerp_takes_the_short_arc():
    a = quat.identity()
    b = -quat.from_axis_angle([0, 1, 0], 0.2)  # same rotation as +0.2 rad, opposite sign
    mid = quat.slerp(a, b, 0.5)
    assert quat.angle(mid) == pytest.approx(0.1)


def test_slerp_constant_speed():
    a = quat.identity()
    b = quat.from_axis_angle([1, 0, 0], 2.0)
    t = np.linspace(0, 1, 11)
    angles = quat.angle(quat.slerp(a, b, t))
    assert np.allclose(angles, 2.0 * t, atol=1e-12)


def test_between_maps_u_to_v(rng):
    u, v = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    q = quat.between(u, v)
    unit = v / np.linalg.norm(v, axis=-1, keepdims=True)
    got = quat.rotate(q, u / np.linalg.norm(u, axis=-1, keepdims=True))
    assert np.allclose(got, unit, atol=1e-12)


def test_between_opposite_vectors():
    q = quat.between([1.0, 0.0, 0.0], [-1.0, 0.0, 0.0])
    assert np.allclose(quat.rotate(q, [1.0, 0.0, 0.0]), [-1.0, 0.0, 0.0], atol=1e-12)


def test_normalize_and_zero():
    q = quat.normalize([[0.0, 0.0, 0.0, 2.0], [0.0, 0.0, 0.0, 0.0]])
    assert np.array_equal(q, [[0, 0, 0, 1.0], [0, 0, 0, 1.0]])


def test_unroll_makes_sequence_continuous(rng):
    q = random_quats(rng, (1,))[0]
    seq = np.stack([q * s for s in (1, -1, -1, 1, -1)])
    out = quat.unroll(seq)
    assert np.all(np.sum(out[1:] * out[:-1], axis=-1) > 0)
    assert np.array_equal(seq[1], q * -1)  # input untouched


def test_yaw_round_trip():
    theta = np.linspace(-3.0, 3.0, 13)
    assert np.allclose(quat.yaw(quat.from_yaw(theta)), theta, atol=1e-12)


def test_functions_do_not_mutate_inputs(rng):
    a, b = random_quats(rng, (8,)), random_quats(rng, (8,))
    a0, b0 = a.copy(), b.copy()
    v = rng.normal(size=(8, 3))
    v0 = v.copy()
    quat.mul(a, b), quat.inv(a), quat.rotate(a, v), quat.slerp(a, b, 0.3), quat.unroll(a), quat.log(a)
    assert np.array_equal(a, a0) and np.array_equal(b, b0) and np.array_equal(v, v0)


def test_rotate_checks_shapes():
    with pytest.raises(ValueError, match=r"Expected `q` of shape \(\.\.\., 4\) and `v` of shape \(\.\.\., 3\), got \(4,\) and \(4,\)"):
        quat.rotate([0, 0, 0, 1.0], [1.0, 2, 3, 4])
    with pytest.raises(ValueError, match="got"):
        quat.rotate([0, 0, 1.0], [1.0, 2, 3])
