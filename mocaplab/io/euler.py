"""Euler angles, used only by the file formats.

An Euler order is a string of axes such as ``"ZYX"``; angles are applied as
*intrinsic* rotations in the order written, so ``"ZYX"`` with angles
``(a, b, c)`` is ``R = Rz(a) @ Ry(b) @ Rx(c)``.  This is the meaning of BVH
channel order and of scipy's upper-case sequences
(``Rotation.from_euler("ZYX", ...)``).

:func:`to_quat` composes the elementary half-angle quaternions directly: it is
the same rotation as ``scipy.spatial.transform.Rotation.from_euler(order, angles)``
(the tests check every order against scipy) but about fifteen times faster on
a whole clip, which matters for reading files.  The reverse conversion,
:func:`from_quat`, is scipy's.
"""

from __future__ import annotations

import warnings

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

from .. import quat

__all__ = ["to_quat", "from_quat"]

_AXIS = {"X": 0, "Y": 1, "Z": 2}


def _check(order: str) -> str:
    up = order.upper()
    if not up or len(up) > 3 or any(c not in _AXIS for c in up) or any(a == b for a, b in zip(up, up[1:])):
        raise ValueError(f"Expected an Euler order of 1 to 3 axes from 'XYZ' (no axis twice in a row), got {order!r}")
    return up


def to_quat(order: str, angles: ArrayLike, *, degrees: bool = True) -> NDArray[np.float64]:
    """Unit quaternions (..., 4) of intrinsic Euler angles (..., len(order))."""
    up = _check(order)
    a = np.asarray(angles, dtype=float)
    if a.shape[-1] != len(up):
        raise ValueError(f"Expected angles with last axis {len(up)} for order {order!r}, got shape {a.shape}")
    if degrees:
        a = np.radians(a)
    half = 0.5 * a
    if len(up) == 3 and len(set(up)) == 3:
        # Tait-Bryan order (i, j, k): expand (c1 + s1 e_i)(c2 + s2 e_j)(c3 + s3 e_k)
        # with e_i e_j = eps e_k, eps = +1 for a cyclic order, -1 otherwise.
        i, j, k = (_AXIS[c] for c in up)
        eps = 1.0 if (i, j, k) in ((0, 1, 2), (1, 2, 0), (2, 0, 1)) else -1.0
        c = np.cos(half)
        s = np.sin(half)
        c1, c2, c3 = c[..., 0], c[..., 1], c[..., 2]
        s1, s2, s3 = s[..., 0], s[..., 1], s[..., 2]
        out = np.empty(a.shape[:-1] + (4,))
        out[..., 3] = c1 * c2 * c3 - eps * s1 * s2 * s3
        out[..., i] = s1 * c2 * c3 + eps * c1 * s2 * s3
        out[..., j] = c1 * s2 * c3 - eps * s1 * c2 * s3
        out[..., k] = c1 * c2 * s3 + eps * s1 * s2 * c3
        return out
    result = None
    for n, axis in enumerate(up):
        q = np.zeros(a.shape[:-1] + (4,))
        q[..., _AXIS[axis]] = np.sin(half[..., n])
        q[..., 3] = np.cos(half[..., n])
        result = q if result is None else quat.mul(result, q)
    assert result is not None
    return result


def from_quat(order: str, q: ArrayLike, *, degrees: bool = True) -> NDArray[np.float64]:
    """Intrinsic Euler angles (..., 3) of unit quaternions, via scipy.

    At gimbal lock scipy sets the third angle to zero; the rotation is still
    exact, so the warning it raises is silenced.
    """
    up = _check(order)
    if len(up) != 3:
        raise ValueError(f"Expected a three-axis order to convert to, got {order!r}")
    q = np.asarray(q, dtype=float)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        e = Rotation.from_quat(q.reshape(-1, 4)).as_euler(up, degrees=degrees)
    return e.reshape(q.shape[:-1] + (3,))
