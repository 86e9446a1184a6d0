"""Unit quaternions as small broadcasting functions.

Conventions (used everywhere in mocaplab)
-----------------------------------------
* A quaternion is an array whose last axis has length 4, ordered
  ``(x, y, z, w)``: vector part first, scalar last.  This is the order of
  :class:`scipy.spatial.transform.Rotation` (``as_quat()`` default), so arrays
  pass to and from scipy without shuffling.
* ``mul(a, b)`` is the Hamilton product: rotating a vector by ``mul(a, b)``
  first applies ``b`` and then ``a`` (the same as the matrix product
  ``A @ B``).
* Rotation vectors (``log``/``exp``) are axis times angle in radians.

Every function broadcasts over leading axes, so one function serves a single
pose ``(J, 4)``, a clip ``(F, J, 4)`` or a batch.  Nothing here mutates its
arguments.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "identity",
    "mul",
    "mul_components",
    "left_matrix",
    "inv",
    "normalize",
    "rotate",
    "slerp",
    "log",
    "exp",
    "between",
    "from_axis_angle",
    "unroll",
    "angle",
    "to_matrix",
    "from_matrix",
    "yaw",
    "from_yaw",
]

Array = NDArray[np.float64]


def identity(shape: tuple[int, ...] = ()) -> Array:
    """Identity quaternions of the given leading shape, shape ``shape + (4,)``."""
    q = np.zeros(tuple(shape) + (4,))
    q[..., 3] = 1.0
    return q


def mul(a: ArrayLike, b: ArrayLike) -> Array:
    """Hamilton product ``a * b`` (apply ``b`` first, then ``a``)."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0], out[..., 1], out[..., 2], out[..., 3] = mul_components(np.moveaxis(a, -1, 0), np.moveaxis(b, -1, 0))
    return out


def mul_components(a: Array | Sequence[Array], b: Array | Sequence[Array]) -> tuple[Array, Array, Array, Array]:
    """The Hamilton product ``a * b`` written once, on components.

    ``a`` and ``b`` are ``(x, y, z, w)`` components: sequences of four
    arrays, or arrays whose first axis has length 4 (any broadcasting
    shapes after it); returns the four components of the product.
    :func:`mul` uses it on ``(..., 4)`` arrays and
    :func:`mocaplab.kinematics.fk` on component-major ``(4, J, F)``
    buffers, where one contiguous block per component is faster than
    strided views.

    Examples
    --------
    >>> import numpy as np
    >>> x90 = np.array([np.sin(np.pi / 4), 0.0, 0.0, np.cos(np.pi / 4)])
    >>> np.round(mul_components(x90, x90), 6).tolist()  # two quarter turns: a half turn
    [1.0, 0.0, 0.0, 0.0]
    """
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    )


#: Left-multiplication matrix of a quaternion (x, y, z, w): (q g)_i = sum_j
#: _SIGN[i, j] q[_INDEX[i, j]] g_j (the Hamilton product of :func:`mul_components` as a matrix).
_INDEX = np.array([[3, 2, 1, 0], [2, 3, 0, 1], [1, 0, 3, 2], [0, 1, 2, 3]])
_SIGN = np.array([[1.0, -1.0, 1.0, 1.0], [1.0, 1.0, -1.0, 1.0], [-1.0, 1.0, 1.0, 1.0], [-1.0, -1.0, -1.0, 1.0]])


def left_matrix(q: ArrayLike) -> Array:
    """The Hamilton product ``q * g`` as a matrix acting on ``g``: shape (..., 4, 4), ``L(q) @ g == mul(q, g)``.

    For many products by the same ``q`` (a batched matrix product is
    cheaper than the component formulas there: physical touch-up turns
    every joint of a part by one rotation per frame).

    Examples
    --------
    >>> import numpy as np
    >>> q, g = normalize(np.array([0.1, 0.2, 0.3, 0.9])), normalize(np.array([-0.4, 0.1, 0.2, 0.8]))
    >>> bool(np.allclose(left_matrix(q) @ g, mul(q, g)))
    True
    """
    q = np.asarray(q, dtype=float)
    out: Array = q[..., _INDEX] * _SIGN
    return out


def inv(q: ArrayLike) -> Array:
    """Inverse of unit quaternions (the conjugate)."""
    q = np.asarray(q, dtype=float)
    return q * np.array([-1.0, -1.0, -1.0, 1.0])


def normalize(q: ArrayLike, *, eps: float = 1e-12) -> Array:
    """Scale quaternions to unit length; zero quaternions become identity."""
    q = np.asarray(q, dtype=float)
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    out = np.where(n > eps, q / np.maximum(n, eps), identity(q.shape[:-1]))
    return out


def rotate(q: ArrayLike, v: ArrayLike) -> Array:
    """Rotate vectors ``v`` (..., 3) by unit quaternions ``q`` (..., 4)."""
    q = np.asarray(q, dtype=float)
    v = np.asarray(v, dtype=float)
    if q.shape[-1:] != (4,) or v.shape[-1:] != (3,):
        raise ValueError(f"Expected `q` of shape (..., 4) and `v` of shape (..., 3), got {q.shape} and {v.shape}")
    qx, qy, qz, qw = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    vx, vy, vz = v[..., 0], v[..., 1], v[..., 2]
    # t = 2 (u x v);  v' = v + w t + u x t
    tx = 2.0 * (qy * vz - qz * vy)
    ty = 2.0 * (qz * vx - qx * vz)
    tz = 2.0 * (qx * vy - qy * vx)
    shape = np.broadcast_shapes(q.shape[:-1], v.shape[:-1]) + (3,)
    out = np.empty(shape)
    out[..., 0] = vx + qw * tx + (qy * tz - qz * ty)
    out[..., 1] = vy + qw * ty + (qz * tx - qx * tz)
    out[..., 2] = vz + qw * tz + (qx * ty - qy * tx)
    return out


def angle(q: ArrayLike) -> Array:
    """Rotation angle of unit quaternions in radians, in ``[0, pi]``."""
    q = np.asarray(q, dtype=float)
    s = np.linalg.norm(q[..., :3], axis=-1)
    return 2.0 * np.arctan2(s, np.abs(q[..., 3]))


def log(q: ArrayLike) -> Array:
    """Rotation vector (axis * angle, radians) of unit quaternions, shape (..., 3).

    The shorter rotation is returned (``q`` and ``-q`` give the same vector).
    """
    q = np.asarray(q, dtype=float)
    q = np.where(q[..., 3:4] < 0.0, -q, q)
    v = q[..., :3]
    s = np.linalg.norm(v, axis=-1, keepdims=True)
    half = np.arctan2(s, q[..., 3:4])
    # 2*half/s -> 2/w as s -> 0 (series limit keeps small angles exact)
    small = s < 1e-8
    scale = np.where(small, 2.0 / np.maximum(q[..., 3:4], 1e-12), 2.0 * half / np.where(small, 1.0, s))
    return v * scale


def exp(r: ArrayLike) -> Array:
    """Unit quaternions from rotation vectors (axis * angle, radians)."""
    r = np.asarray(r, dtype=float)
    theta = np.linalg.norm(r, axis=-1, keepdims=True)
    half = 0.5 * theta
    small = theta < 1e-8
    k = np.where(small, 0.5 - theta**2 / 48.0, np.sin(half) / np.where(small, 1.0, theta))
    return np.concatenate([r * k, np.cos(half)], axis=-1)


def from_axis_angle(axis: ArrayLike, angle_rad: ArrayLike) -> Array:
    """Quaternions rotating by ``angle_rad`` about ``axis`` (normalised here)."""
    axis = np.asarray(axis, dtype=float)
    n = np.linalg.norm(axis, axis=-1, keepdims=True)
    unit = axis / np.where(n > 0, n, 1.0)
    return exp(unit * np.asarray(angle_rad, dtype=float)[..., None])


def slerp(a: ArrayLike, b: ArrayLike, t: ArrayLike) -> Array:
    """Spherical linear interpolation from ``a`` (t=0) to ``b`` (t=1).

    Takes the shorter arc; ``t`` broadcasts against the leading axes.
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    t = np.asarray(t, dtype=float)[..., None]
    d = np.sum(a * b, axis=-1, keepdims=True)
    b = np.where(d < 0.0, -b, b)
    d = np.abs(d)
    rel = mul(b, inv(a))
    rel = np.where(rel[..., 3:4] < 0, -rel, rel)
    return normalize(mul(exp(log(rel) * t), a))


def between(u: ArrayLike, v: ArrayLike) -> Array:
    """Shortest-arc unit quaternions rotating direction ``u`` onto ``v``.

    For opposite vectors an arbitrary perpendicular axis is used.
    """
    ua = np.asarray(u, dtype=float)
    va = np.asarray(v, dtype=float)
    ua = ua / np.linalg.norm(ua, axis=-1, keepdims=True)
    va = va / np.linalg.norm(va, axis=-1, keepdims=True)
    c = np.cross(ua, va)
    d = np.sum(ua * va, axis=-1, keepdims=True)
    q = np.concatenate([c, 1.0 + d], axis=-1)
    opposite = (1.0 + d[..., 0]) < 1e-9
    if np.any(opposite):
        # any axis perpendicular to u
        alt = np.cross(ua, np.array([1.0, 0.0, 0.0]))
        weak = np.linalg.norm(alt, axis=-1) < 1e-6
        alt = np.where(weak[..., None], np.cross(ua, np.array([0.0, 0.0, 1.0])), alt)
        q = np.where(opposite[..., None], np.concatenate([alt, np.zeros_like(d)], axis=-1), q)
    return normalize(q)


def unroll(q: ArrayLike, *, axis: int = 0) -> Array:
    """Flip signs along ``axis`` (time) so consecutive quaternions are close.

    ``q`` and ``-q`` are the same rotation; filters and splines need the
    continuous choice.
    """
    q = np.array(q, dtype=float, copy=True)
    q = np.moveaxis(q, axis, 0)
    if q.shape[0] > 1:
        d = np.sum(q[1:] * q[:-1], axis=-1)
        flips = np.cumsum(d < 0.0, axis=0) % 2
        q[1:] *= np.where(flips[..., None] == 1, -1.0, 1.0)
    return np.moveaxis(q, 0, axis)


def to_matrix(q: ArrayLike) -> Array:
    """Rotation matrices (..., 3, 3) of unit quaternions."""
    q = np.asarray(q, dtype=float)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    m = np.stack(
        [
            1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w),
            2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
            2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y),
        ],
        axis=-1,
    )
    return m.reshape(q.shape[:-1] + (3, 3))


def from_matrix(m: ArrayLike) -> Array:
    """Unit quaternions of rotation matrices (..., 3, 3) (via scipy)."""
    from scipy.spatial.transform import Rotation

    m = np.asarray(m, dtype=float)
    flat = Rotation.from_matrix(m.reshape(-1, 3, 3)).as_quat()
    return flat.reshape(m.shape[:-2] + (4,))


def yaw(q: ArrayLike) -> Array:
    """Heading angle about +Y (radians) of the rotated +Z axis.

    The heading of a character is where its local forward axis (+Z) points on
    the ground plane: ``atan2(f_x, f_z)``.
    """
    f = rotate(q, np.array([0.0, 0.0, 1.0]))
    return np.arctan2(f[..., 0], f[..., 2])


def from_yaw(theta: ArrayLike) -> Array:
    """Quaternions rotating by ``theta`` radians about the +Y (up) axis."""
    theta = np.asarray(theta, dtype=float)
    half = 0.5 * theta
    z = np.zeros_like(theta)
    return np.stack([z, np.sin(half), z, np.cos(half)], axis=-1)
