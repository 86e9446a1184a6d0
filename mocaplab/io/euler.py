"""Euler angles, used only by the file formats.

An Euler order is a string of axes such as ``"ZYX"``; angles are applied as
*intrinsic* rotations in the order written, so ``"ZYX"`` with angles
``(a, b, c)`` is ``R = Rz(a) @ Ry(b) @ Rx(c)``.  This is the meaning of BVH
channel order and of scipy's upper-case sequences
(``Rotation.from_euler("ZYX", ...)``).  One- and two-axis orders (``"X"``,
``"ZX"``) are allowed for :func:`to_quat` (BVH joints with fewer rotation
channels, Acclaim bones with fewer dofs).

:func:`to_quat` composes the elementary half-angle quaternions directly: it is
the same rotation as ``scipy.spatial.transform.Rotation.from_euler(order, angles)``
(the tests check every order against scipy) but several times faster on a
whole clip, which matters for reading files.  The half-angle cosines and sines
come from the tangent of the quarter angle, ``u = tan(a / 4)``:
``cos(a / 2) = (1 - u**2) / (1 + u**2)`` and ``sin(a / 2) = 2 u / (1 + u**2)``
(exact identities, valid for every angle; numpy's vectorised ``tan`` is much
faster than ``sin`` plus ``cos`` and the result agrees with them to 1e-15).
The reverse conversion, :func:`from_quat`, is scipy's.
"""

from __future__ import annotations

import warnings

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

__all__ = ["to_quat", "from_quat"]

_AXIS = {"X": 0, "Y": 1, "Z": 2}
_CYCLIC = ((0, 1, 2), (1, 2, 0), (2, 0, 1))


def _check(order: str) -> str:
    if not isinstance(order, str):
        raise ValueError(f"Expected an Euler order string such as 'ZYX', got {order!r}")
    up = order.upper()
    if not up or len(up) > 3 or any(c not in _AXIS for c in up) or len(set(up)) != len(up):
        raise ValueError(f"Expected an Euler order of 1 to 3 distinct axes from 'XYZ', got {order!r}")
    return up


def _half_cos_sin(comp: NDArray[np.float64], scale: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``cos(scale * a / 2)`` and ``sin(scale * a / 2)`` through ``tan(scale * a / 4)``.

    ``comp`` is any array of angles; the results are new C-contiguous arrays
    (computed in place to spare allocations on whole clips).
    """
    u = np.multiply(comp, 0.25 * scale, order="C")
    np.tan(u, out=u)
    c = u * u
    d = c + 1.0
    np.reciprocal(d, out=d)
    np.subtract(1.0, c, out=c)
    c *= d
    u *= d
    u *= 2.0
    return c, u


def to_quat(order: str, angles: ArrayLike, *, degrees: bool = True) -> NDArray[np.float64]:
    """Unit quaternions of intrinsic Euler angles.

    Parameters
    ----------
    order : str
        One to three distinct axes, e.g. ``"ZYX"`` (intrinsic, applied in the
        order written: ``Rz @ Ry @ Rx``), ``"ZX"`` or ``"Y"``.
    angles : array_like, shape (..., len(order))
        Angles in the order of ``order``.
    degrees : bool
        Angles in degrees (default) or radians.

    Returns
    -------
    ndarray, shape (..., 4)
        Quaternions ``(x, y, z, w)``.

    Examples
    --------
    >>> to_quat("ZYX", [90.0, 0.0, 0.0]).round(6).tolist()
    [0.0, 0.0, 0.707107, 0.707107]
    """
    up = _check(order)
    a = np.asarray(angles, dtype=float)
    if a.ndim == 0 or a.shape[-1] != len(up):
        raise ValueError(f"Expected angles with last axis {len(up)} for order {order!r}, got shape {a.shape}")
    lead = a.shape[:-1]
    k = len(up)
    if a.size == 0:
        return np.empty(lead + (4,))
    axes = tuple(_AXIS[ch] for ch in up)
    scale = np.pi / 180.0 if degrees else 1.0
    # (M, G, k): a view even for column slices of a larger table such as a BVH
    # channel matrix, so no full-size copy is made
    a3 = a.reshape(lead[0] if lead else 1, -1, k)
    n_rows, n_per_row = a3.shape[:2]
    out = np.empty((n_rows, n_per_row, 4))
    # blocks small enough for the temporaries to stay in cache (and below the
    # allocator's default 128 KiB mmap threshold, which spares page faults)
    step = max(1, _BLOCK // n_per_row)
    for start in range(0, n_rows, step):
        rows = slice(start, start + step)
        block = a3[rows].reshape(-1, k)
        dst = out[rows].reshape(-1, 4)
        _compose(axes, block.T, scale, [dst[:, 0], dst[:, 1], dst[:, 2], dst[:, 3]])
    return out.reshape(lead + (4,))


_BLOCK = 5000


def to_quat_channels(
    order: str, channels: list[NDArray[np.float64]], out: NDArray[np.float64], *, degrees: bool = True
) -> NDArray[np.float64]:
    """Like :func:`to_quat`, in component-major layout (for file readers).

    Parameters
    ----------
    order : str
        As for :func:`to_quat`.
    channels : list of ndarray, each shape (G, F)
        One array per axis of ``order``: the angle of each of G joints on each
        of F frames (views into a channel table are fine).
    out : ndarray, shape (4, G, F)
        Written in place with the quaternion components ``x, y, z, w``.

    Returns
    -------
    ndarray, shape (4, G, F)
        ``out``.
    """
    up = _check(order)
    if len(channels) != len(up) or out.ndim != 3 or out.shape[0] != 4:
        raise ValueError(f"Expected {len(up)} channel arrays and `out` of shape (4, G, F), got {len(channels)} and {out.shape}")
    axes = tuple(_AXIS[ch] for ch in up)
    scale = np.pi / 180.0 if degrees else 1.0
    n_joints, n_frames = out.shape[1:]
    step = max(1, _BLOCK // max(n_frames, 1))
    for start in range(0, n_joints, step):
        rows = slice(start, start + step)
        block = np.stack([np.asarray(ch[rows], dtype=float) for ch in channels]).reshape(len(up), -1)
        _compose(axes, block, scale, [out[c, rows].reshape(-1) for c in range(4)])
    return out


def _compose(
    axes: tuple[int, ...], comp: NDArray[np.float64], scale: float, out: list[NDArray[np.float64]]
) -> None:
    """Write the quaternions of angles ``comp`` (k, n) about ``axes`` into the
    four component arrays ``out`` (each (n,), views allowed)."""
    c, s = _half_cos_sin(comp, scale)
    if len(axes) == 3:
        # (c1 + s1 e_i)(c2 + s2 e_j)(c3 + s3 e_k) with e_i e_j = eps e_k,
        # eps = +1 for a cyclic order of distinct axes, -1 otherwise:
        #   w = c1c2c3 - eps s1s2s3      i = s1c2c3 + eps c1s2s3
        #   j = c1s2c3 - eps s1c2s3      k = c1c2s3 + eps s1s2c3
        i, j, k = axes
        eps = 1.0 if (i, j, k) in _CYCLIC else -1.0
        c1, c2, c3 = c
        s1, s2, s3 = s
        es3 = s3 if eps > 0 else -s3
        cc, ss, cs, sc = c1 * c2, s1 * s2, c1 * s2, s1 * c2
        out[3][...] = cc * c3 - ss * es3
        out[i][...] = sc * c3 + cs * es3
        out[j][...] = cs * c3 - sc * es3
        out[k][...] = cc * s3 + eps * (ss * c3)
    elif len(axes) == 2:
        # (c1 + s1 e_i)(c2 + s2 e_j) = c1c2 + s1c2 e_i + c1s2 e_j + eps s1s2 e_k
        i, j = axes
        k = 3 - i - j
        eps = 1.0 if (i, j, k) in _CYCLIC else -1.0
        out[3][...] = c[0] * c[1]
        out[i][...] = s[0] * c[1]
        out[j][...] = c[0] * s[1]
        out[k][...] = eps * (s[0] * s[1])
    else:
        for a in range(3):
            out[a][...] = s[0] if a == axes[0] else 0.0
        out[3][...] = c[0]


def from_quat(order: str, q: ArrayLike, *, degrees: bool = True) -> NDArray[np.float64]:
    """Intrinsic Euler angles of unit quaternions, via scipy.

    Parameters
    ----------
    order : str
        Three distinct axes, e.g. ``"ZYX"``.
    q : array_like, shape (..., 4)
    degrees : bool

    Returns
    -------
    ndarray, shape (..., 3)

    Notes
    -----
    At gimbal lock scipy sets the third angle to zero; the rotation is still
    exact, so the warning it raises is silenced.
    """
    up = _check(order)
    if len(up) != 3:
        raise ValueError(f"Expected a three-axis order to convert to, got {order!r}")
    q = np.asarray(q, dtype=float)
    if q.ndim == 0 or q.shape[-1] != 4:
        raise ValueError(f"Expected quaternions of shape (..., 4), got {q.shape}")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        e = Rotation.from_quat(q.reshape(-1, 4)).as_euler(up, degrees=degrees)
    return e.reshape(q.shape[:-1] + (3,))
